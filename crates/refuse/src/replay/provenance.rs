//! Where a fused log came from, recorded so that the same input and configuration give the
//! same bytes from every door (the CLI from any working directory, the Python package, a Ray
//! task): file names and a content digest, never a path as it was typed.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;

use sha2::{Digest as _, Sha256};

/// The input's digest, computed on a thread of its own beside the replay.
pub struct InputDigest {
    path: PathBuf,
    thread: JoinHandle<std::io::Result<String>>,
}

impl InputDigest {
    pub fn start(path: &Path) -> Self {
        let input = path.to_owned();
        let thread = std::thread::Builder::new()
            .name("input-digest".into())
            .spawn(move || sha256_of_file(&input))
            .expect("a thread starts");
        InputDigest {
            path: path.to_owned(),
            thread,
        }
    }

    /// The digest (hex), or the error of reading the input.
    pub fn finish(self) -> Result<String, railfuse_catalog::Error> {
        let digest = self
            .thread
            .join()
            .expect("the digest thread does not panic");
        digest.map_err(|source| railfuse_catalog::Error::Io {
            path: self.path,
            source,
        })
    }
}

/// The SHA-256 of a file's content, in lower-case hex; read in 1 MiB blocks.
pub fn sha256_of_file(path: &Path) -> std::io::Result<String> {
    let mut file = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let mut block = vec![0u8; 1 << 20];
    loop {
        let n = file.read(&mut block)?;
        if n == 0 {
            break;
        }
        hasher.update(&block[..n]);
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// The last component of a path as it was given ("embedded default" and other names that are
/// not paths stay as they are).
pub fn file_name(given: &str) -> String {
    Path::new(given)
        .file_name()
        .map_or_else(|| given.to_owned(), |n| n.to_string_lossy().into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_digests_do_not_depend_on_how_a_path_is_written() {
        assert_eq!(file_name("samples/kalman.toml"), "kalman.toml");
        assert_eq!(file_name("/abs/dir/kalman.toml"), "kalman.toml");
        assert_eq!(file_name("embedded default"), "embedded default");
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("abc");
        std::fs::write(&p, b"abc").unwrap();
        // FIPS 180-2's example.
        assert_eq!(
            sha256_of_file(&p).unwrap(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
