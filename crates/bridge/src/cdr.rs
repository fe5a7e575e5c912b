//! Plain CDR (OMG XCDR version 1), the serialisation of every ROS 2 message
//! on the wire: a 4-byte encapsulation header, then the fields in order,
//! each primitive aligned to its own size (at most 8) counted from the end
//! of the header; strings as a `uint32` length that counts the terminating
//! NUL, the bytes and the NUL; sequences as a `uint32` element count and the
//! elements; fixed arrays without a count (OMG DDS-XTypes 1.3, §7.4.3.5;
//! rmw_zenoh sends the bytes its CDR type support writes, with the header
//! `00 01 00 00` — little endian — on every little-endian host).
//!
//! [`CdrWriter`] writes little endian only. [`CdrReader`] reads both byte
//! orders (a big-endian host's publisher writes `00 00 00 00`) and never
//! panics on malformed input: every read is bounds-checked and returns
//! [`CdrError`].

use thiserror::Error;

/// Encapsulation header of plain CDR, little endian (representation
/// identifier `CDR_LE` = 0x0001, options 0).
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Encapsulation header of plain CDR, big endian (`CDR_BE` = 0x0000).
pub const CDR_BE_HEADER: [u8; 4] = [0x00, 0x00, 0x00, 0x00];

/// Longest string or sequence a reader accepts (elements): a remote message
/// cannot make the bridge allocate more than this per field.
pub const MAX_READ_LEN: usize = 1 << 16;

/// Why a CDR message could not be read.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CdrError {
    /// The payload is shorter than the encapsulation header.
    #[error("the payload has {0} bytes, fewer than the 4-byte CDR header")]
    NoHeader(usize),
    /// The encapsulation is not plain CDR.
    #[error("unsupported CDR encapsulation {0:02x?} (plain CDR, XCDR1, is expected)")]
    Encapsulation([u8; 2]),
    /// A field runs past the end of the payload.
    #[error("the payload ends inside field {field} (at byte {at} of {len})")]
    Truncated {
        field: &'static str,
        at: usize,
        len: usize,
    },
    /// A string or sequence length beyond [`MAX_READ_LEN`].
    #[error("field {field} claims {len} elements (at most {MAX_READ_LEN})")]
    TooLong { field: &'static str, len: usize },
    /// A string without its NUL or with invalid UTF-8.
    #[error("field {0} is not a NUL-terminated UTF-8 string")]
    BadString(&'static str),
}

/// Writes one message: [`CdrWriter::start`] (header), the fields, then
/// [`CdrWriter::bytes`]. The buffer is kept between messages, so a writer
/// reused for a stream allocates only while its messages grow.
#[derive(Debug, Default, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl CdrWriter {
    /// An empty writer (call [`CdrWriter::start`] before the fields).
    pub fn new() -> CdrWriter {
        CdrWriter::default()
    }

    /// Clears the buffer and writes the little-endian encapsulation header.
    pub fn start(&mut self) -> &mut Self {
        self.buf.clear();
        self.buf.extend_from_slice(&CDR_LE_HEADER);
        self
    }

    /// The message written so far, header included.
    pub fn bytes(&self) -> &[u8] {
        &self.buf
    }

    /// Pads with zeros to a multiple of `n` bytes after the header.
    fn align(&mut self, n: usize) {
        let offset = self.buf.len() - CDR_LE_HEADER.len();
        let pad = (n - offset % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// An `octet`/`uint8`.
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.buf.push(v);
        self
    }

    /// A `boolean` (one byte, 0 or 1).
    pub fn bool(&mut self, v: bool) -> &mut Self {
        self.u8(u8::from(v))
    }

    /// A `uint32`.
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `uint64`.
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// An `int64`.
    pub fn i64(&mut self, v: i64) -> &mut Self {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `float64`, bit for bit (NaN payloads included).
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `string`: length with the NUL, the bytes, the NUL. (ROS strings
    /// must not contain NUL; the writers here only write names.)
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        self
    }

    /// The element count of a sequence (the elements follow).
    pub fn seq_len(&mut self, n: usize) -> &mut Self {
        self.u32(n as u32)
    }

    /// A sequence of 8-byte elements: the count, the alignment (only when
    /// there are elements), the elements' little-endian bytes.
    fn seq_8(&mut self, n: usize, bytes: impl Iterator<Item = [u8; 8]>) -> &mut Self {
        self.seq_len(n);
        if n > 0 {
            self.align(8);
            bytes.for_each(|b| self.buf.extend_from_slice(&b));
        }
        self
    }

    /// A `float64[]`.
    pub fn seq_f64(&mut self, v: &[f64]) -> &mut Self {
        self.seq_8(v.len(), v.iter().map(|x| x.to_le_bytes()))
    }

    /// A `uint64[]`.
    pub fn seq_u64(&mut self, v: &[u64]) -> &mut Self {
        self.seq_8(v.len(), v.iter().map(|x| x.to_le_bytes()))
    }

    /// A `string[]`.
    pub fn seq_string<S: AsRef<str>>(&mut self, v: &[S]) -> &mut Self {
        self.seq_len(v.len());
        for s in v {
            self.string(s.as_ref());
        }
        self
    }

    /// A fixed `uint8[N]` (no count).
    pub fn u8_array(&mut self, v: &[u8]) -> &mut Self {
        self.buf.extend_from_slice(v);
        self
    }
}

/// Reads one message, field by field, in the order of its definition.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    data: &'a [u8],
    /// Position in `data` (the header included).
    pos: usize,
    little: bool,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header (plain CDR, either byte order).
    pub fn new(data: &'a [u8]) -> Result<CdrReader<'a>, CdrError> {
        if data.len() < 4 {
            return Err(CdrError::NoHeader(data.len()));
        }
        let little = match [data[0], data[1]] {
            [0x00, 0x01] => true,
            [0x00, 0x00] => false,
            other => return Err(CdrError::Encapsulation(other)),
        };
        Ok(CdrReader {
            data,
            pos: 4,
            little,
        })
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    fn take(&mut self, field: &'static str, align: usize, n: usize) -> Result<&'a [u8], CdrError> {
        let offset = self.pos - 4;
        let start = self.pos + (align - offset % align) % align;
        let end = start.checked_add(n).filter(|&e| e <= self.data.len());
        match end {
            Some(end) => {
                self.pos = end;
                Ok(&self.data[start..end])
            }
            None => Err(CdrError::Truncated {
                field,
                at: start.min(self.data.len()),
                len: self.data.len(),
            }),
        }
    }

    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], CdrError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(field, N, N)?);
        if !self.little {
            a.reverse();
        }
        Ok(a)
    }

    /// An `octet`/`uint8`.
    pub fn u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        Ok(self.take(field, 1, 1)?[0])
    }

    /// A `boolean` (any non-zero byte is true).
    pub fn bool(&mut self, field: &'static str) -> Result<bool, CdrError> {
        Ok(self.u8(field)? != 0)
    }

    /// A `uint32`.
    pub fn u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.array(field)?))
    }

    /// An `int32`.
    pub fn i32(&mut self, field: &'static str) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.array(field)?))
    }

    /// A `uint64`.
    pub fn u64(&mut self, field: &'static str) -> Result<u64, CdrError> {
        Ok(u64::from_le_bytes(self.array(field)?))
    }

    /// An `int64`.
    pub fn i64(&mut self, field: &'static str) -> Result<i64, CdrError> {
        Ok(i64::from_le_bytes(self.array(field)?))
    }

    /// A `float64`.
    pub fn f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.array(field)?))
    }

    /// The element count of a sequence, at most [`MAX_READ_LEN`].
    pub fn seq_len(&mut self, field: &'static str) -> Result<usize, CdrError> {
        let len = self.u32(field)? as usize;
        if len > MAX_READ_LEN {
            return Err(CdrError::TooLong { field, len });
        }
        Ok(len)
    }

    /// A `string`.
    pub fn string(&mut self, field: &'static str) -> Result<&'a str, CdrError> {
        let len = self.seq_len(field)?;
        if len == 0 {
            // Some writers send an empty string as length 0 (no NUL).
            return Ok("");
        }
        let bytes = self.take(field, 1, len)?;
        match bytes.split_last() {
            Some((0, text)) => std::str::from_utf8(text).map_err(|_| CdrError::BadString(field)),
            _ => Err(CdrError::BadString(field)),
        }
    }

    /// A `float64[]`, appended to `out` (cleared first).
    pub fn seq_f64(&mut self, field: &'static str, out: &mut Vec<f64>) -> Result<(), CdrError> {
        let len = self.seq_len(field)?;
        out.clear();
        for _ in 0..len {
            out.push(self.f64(field)?);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_are_aligned_after_the_header() {
        let mut w = CdrWriter::new();
        w.start().u8(7).u32(0x0102_0304).u8(1).f64(1.5).string("ab");
        let b = w.bytes();
        assert_eq!(&b[..4], &CDR_LE_HEADER);
        // u8 at 0, pad to 4, u32 at 4..8, u8 at 8, pad to 16, f64 at 16..24,
        // string length at 24..28, "ab\0" at 28..31 (offsets after the header).
        let body = &b[4..];
        assert_eq!(body[0], 7);
        assert_eq!(&body[1..4], &[0, 0, 0]);
        assert_eq!(&body[4..8], &[4, 3, 2, 1]);
        assert_eq!(body[8], 1);
        assert_eq!(&body[9..16], &[0; 7]);
        assert_eq!(&body[16..24], &1.5f64.to_le_bytes());
        assert_eq!(&body[24..28], &3u32.to_le_bytes());
        assert_eq!(&body[28..], b"ab\0");
    }

    #[test]
    fn empty_sequences_have_no_padding_and_doubles_keep_their_bits() {
        let mut w = CdrWriter::new();
        let nan = f64::from_bits(0x7ff8_0000_dead_beef);
        w.start().seq_f64(&[]).seq_f64(&[nan, -0.0]);
        let body = &w.bytes()[4..];
        assert_eq!(&body[..4], &[0; 4], "empty sequence: count 0 only");
        assert_eq!(&body[4..8], &2u32.to_le_bytes());
        assert_eq!(&body[8..16], &nan.to_bits().to_le_bytes());
        assert_eq!(&body[16..24], &(-0.0f64).to_bits().to_le_bytes());
        let mut r = CdrReader::new(w.bytes()).unwrap();
        let mut v = Vec::new();
        r.seq_f64("a", &mut v).unwrap();
        assert!(v.is_empty());
        r.seq_f64("b", &mut v).unwrap();
        assert_eq!(v[0].to_bits(), nan.to_bits());
        assert_eq!(v[1].to_bits(), (-0.0f64).to_bits());
        assert_eq!(r.remaining(), 0);
    }

    #[test]
    fn reader_round_trips_the_writer() {
        let mut w = CdrWriter::new();
        w.start()
            .i32(-5)
            .u32(9)
            .string("frame")
            .bool(true)
            .f64(-2.25)
            .seq_string(&["a", "bc"])
            .u8(3);
        let mut r = CdrReader::new(w.bytes()).unwrap();
        assert_eq!(r.i32("i").unwrap(), -5);
        assert_eq!(r.u32("u").unwrap(), 9);
        assert_eq!(r.string("s").unwrap(), "frame");
        assert!(r.bool("b").unwrap());
        assert_eq!(r.f64("f").unwrap(), -2.25);
        assert_eq!(r.seq_len("n").unwrap(), 2);
        assert_eq!(r.string("s0").unwrap(), "a");
        assert_eq!(r.string("s1").unwrap(), "bc");
        assert_eq!(r.u8("o").unwrap(), 3);
    }

    #[test]
    fn big_endian_payloads_are_read() {
        let mut b = CDR_BE_HEADER.to_vec();
        b.extend_from_slice(&7u32.to_be_bytes());
        b.extend_from_slice(&[0; 4]);
        b.extend_from_slice(&0.5f64.to_be_bytes());
        let mut r = CdrReader::new(&b).unwrap();
        assert_eq!(r.u32("u").unwrap(), 7);
        assert_eq!(r.f64("f").unwrap(), 0.5);
    }

    #[test]
    fn malformed_input_is_an_error_not_a_panic() {
        assert_eq!(CdrReader::new(&[0, 1]).unwrap_err(), CdrError::NoHeader(2));
        assert!(matches!(
            CdrReader::new(&[0, 7, 0, 0]).unwrap_err(),
            CdrError::Encapsulation(_)
        ));
        let mut w = CdrWriter::new();
        w.start().u32(1_000_000);
        let mut r = CdrReader::new(w.bytes()).unwrap();
        assert!(matches!(
            r.string("name"),
            Err(CdrError::TooLong { field: "name", .. })
        ));
        let mut w = CdrWriter::new();
        w.start().u32(3);
        let mut r = CdrReader::new(w.bytes()).unwrap();
        let mut v = Vec::new();
        assert!(matches!(
            r.seq_f64("data", &mut v),
            Err(CdrError::Truncated { field: "data", .. })
        ));
        let mut w = CdrWriter::new();
        w.start().u32(2).u8(b'a').u8(b'b');
        let mut r = CdrReader::new(w.bytes()).unwrap();
        assert_eq!(r.string("s"), Err(CdrError::BadString("s")));
        // Every truncation of a valid message fails cleanly.
        let mut w = CdrWriter::new();
        w.start().string("abc").f64(1.0).seq_f64(&[1.0, 2.0]);
        for cut in 0..w.bytes().len() {
            let Ok(mut r) = CdrReader::new(&w.bytes()[..cut]) else {
                continue;
            };
            let ok = r.string("s").and_then(|_| r.f64("f")).and_then(|_| {
                let mut v = Vec::new();
                r.seq_f64("v", &mut v)
            });
            assert!(ok.is_err(), "cut at {cut}");
        }
    }
}
