//! How the URDF reaches the viewer: the server answers Foxglove's asset
//! requests (the protocol's `fetchAsset`) for [`URDF_URI`] with the
//! scenario's URDF, and for other `package://PKG/PATH` or relative URIs
//! with the file PATH under the URDF's directory (meshes), never outside
//! it. A layout's URDF layer points at [`URDF_URI`]; the same text is also
//! published on `/robot_description` for tools that read it from a topic.

use std::path::{Component, Path, PathBuf};

/// The URI under which the server serves the scenario's URDF.
pub const URDF_URI: &str = "package://hcc/robot.urdf";

/// Largest file served, bytes (meshes are a few MB at most).
const MAX_ASSET: u64 = 64 << 20;

/// The files a server hands out.
#[derive(Clone, Debug)]
pub struct Assets {
    urdf: Vec<u8>,
    /// The URDF's directory (canonical).
    root: PathBuf,
}

impl Assets {
    /// Serves `urdf` (the text of the file at `urdf_path`) and the files
    /// below the file's directory.
    pub fn new(urdf_path: &Path, urdf: String) -> Assets {
        let dir = urdf_path.parent().unwrap_or(Path::new("."));
        let root = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
        Assets {
            urdf: urdf.into_bytes(),
            root,
        }
    }

    /// The bytes of `uri`, or why not.
    pub fn fetch(&self, uri: &str) -> Result<Vec<u8>, String> {
        if uri == URDF_URI {
            return Ok(self.urdf.clone());
        }
        let relative = match uri.strip_prefix("package://") {
            // package://PKG/PATH: PATH below the URDF's directory.
            Some(rest) => rest.split_once('/').map(|(_, p)| p).unwrap_or(""),
            None if uri.contains("://") => {
                return Err(format!("{uri}: only package:// URIs are served"));
            }
            None => uri,
        };
        let rel = Path::new(relative);
        if relative.is_empty()
            || rel
                .components()
                .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
        {
            return Err(format!("{uri}: not a path below the URDF's directory"));
        }
        let path = std::fs::canonicalize(self.root.join(rel)).map_err(|e| format!("{uri}: {e}"))?;
        if !path.starts_with(&self.root) {
            return Err(format!("{uri}: outside the URDF's directory"));
        }
        let meta = std::fs::metadata(&path).map_err(|e| format!("{uri}: {e}"))?;
        if !meta.is_file() || meta.len() > MAX_ASSET {
            return Err(format!("{uri}: not a file of at most {MAX_ASSET} bytes"));
        }
        std::fs::read(&path).map_err(|e| format!("{uri}: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serves_the_urdf_and_files_below_it_only() {
        let dir = std::env::temp_dir().join(format!("hcc-view-assets-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("robot/meshes")).unwrap();
        std::fs::write(dir.join("robot/meshes/a.stl"), b"mesh").unwrap();
        std::fs::write(dir.join("secret"), b"no").unwrap();
        let a = Assets::new(&dir.join("robot/r.urdf"), "<robot name=\"r\"/>".into());
        assert_eq!(a.fetch(URDF_URI).unwrap(), b"<robot name=\"r\"/>");
        assert_eq!(a.fetch("package://any/meshes/a.stl").unwrap(), b"mesh");
        assert_eq!(a.fetch("meshes/a.stl").unwrap(), b"mesh");
        for bad in [
            "package://any/../secret",
            "../secret",
            "/etc/hostname",
            "file:///etc/hostname",
            "package://any/",
            "package://any/meshes",
            "package://any/meshes/missing.stl",
        ] {
            assert!(a.fetch(bad).is_err(), "{bad} was served");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
