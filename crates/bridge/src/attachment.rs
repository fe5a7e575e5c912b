//! The attachment rmw_zenoh puts on every message sample and requires from
//! every publisher: the publisher's sequence number (`int64`, +1 per
//! message), the source timestamp (`int64`, ns of the system clock at
//! publication) and the publisher's 16-byte GID, serialised in this order
//! with zenoh-ext's serialiser (rmw_zenoh `attachment_helpers.cpp`,
//! `AttachmentData::serialize_to_zbytes`). On the wire: 8 bytes little
//! endian, 8 bytes little endian, the LEB128 length 16, the 16 GID bytes —
//! 33 bytes.

use zenoh::bytes::ZBytes;
use zenoh_ext::{ZDeserializer, ZSerializer};

/// Bytes of a publisher GID (`RMW_GID_STORAGE_SIZE`).
pub const GID_SIZE: usize = 16;

/// One sample's attachment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// The publisher's sequence number of this sample (from 1).
    pub sequence_number: i64,
    /// Publication time, ns since the Unix epoch (CLOCK_REALTIME).
    pub source_timestamp: i64,
    /// The publisher's GID.
    pub source_gid: [u8; GID_SIZE],
}

impl Attachment {
    /// Serialises it as rmw_zenoh does.
    pub fn to_zbytes(&self) -> ZBytes {
        let mut s = ZSerializer::new();
        s.serialize(self.sequence_number);
        s.serialize(self.source_timestamp);
        s.serialize(self.source_gid);
        s.finish()
    }

    /// Reads a received attachment; `None` when it is missing or malformed
    /// (a publisher that is not rmw_zenoh's).
    pub fn from_zbytes(bytes: Option<&ZBytes>) -> Option<Attachment> {
        let mut d = ZDeserializer::new(bytes?);
        let sequence_number = d.deserialize::<i64>().ok()?;
        let source_timestamp = d.deserialize::<i64>().ok()?;
        let source_gid = d.deserialize::<[u8; GID_SIZE]>().ok()?;
        d.done().then_some(Attachment {
            sequence_number,
            source_timestamp,
            source_gid,
        })
    }
}

/// Current CLOCK_REALTIME in ns since the Unix epoch (the source timestamp
/// rmw_zenoh writes).
pub fn realtime_now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_rmw_zenohs() {
        let gid: [u8; 16] = std::array::from_fn(|i| i as u8 + 1);
        let a = Attachment {
            sequence_number: 0x0102_0304_0506_0708,
            source_timestamp: -2,
            source_gid: gid,
        };
        let bytes = a.to_zbytes().to_bytes().to_vec();
        assert_eq!(bytes.len(), 33);
        assert_eq!(&bytes[..8], &0x0102_0304_0506_0708i64.to_le_bytes());
        assert_eq!(&bytes[8..16], &(-2i64).to_le_bytes());
        assert_eq!(bytes[16], 16, "LEB128 length of the GID");
        assert_eq!(&bytes[17..], &gid);
        assert_eq!(Attachment::from_zbytes(Some(&a.to_zbytes())), Some(a));
    }

    #[test]
    fn foreign_attachments_are_none() {
        assert_eq!(Attachment::from_zbytes(None), None);
        let short = ZBytes::from(vec![1u8, 2, 3]);
        assert_eq!(Attachment::from_zbytes(Some(&short)), None);
        let mut long = Attachment {
            sequence_number: 1,
            source_timestamp: 2,
            source_gid: [0; 16],
        }
        .to_zbytes()
        .to_bytes()
        .to_vec();
        long.push(0);
        assert_eq!(Attachment::from_zbytes(Some(&ZBytes::from(long))), None);
    }
}
