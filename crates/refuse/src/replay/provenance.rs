//! Where a fused log came from, recorded so that the same input and configuration give the
//! same bytes from every door (the CLI from any working directory, the Python package, a Ray
//! task): file names and a content digest, never a path as it was typed.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;

use sha2::{Digest as _, Sha256};

/// The input's digest, computed on a thread of its own beside the replay: of the content of
/// its files one after the other (one file: that file's SHA-256).
pub struct InputDigest {
    thread: JoinHandle<Result<String, (PathBuf, std::io::Error)>>,
}

impl InputDigest {
    pub fn start(files: Vec<PathBuf>) -> Self {
        let thread = std::thread::Builder::new()
            .name("input-digest".into())
            .spawn(move || sha256_of_files(&files))
            .expect("a thread starts");
        InputDigest { thread }
    }

    /// The digest (hex), or the error of reading the input.
    pub fn finish(self) -> Result<String, railfuse_catalog::Error> {
        let digest = self
            .thread
            .join()
            .expect("the digest thread does not panic");
        digest.map_err(|(path, source)| railfuse_catalog::Error::Io { path, source })
    }
}

/// The SHA-256 of the files' contents one after the other, in lower-case hex; read in 1 MiB
/// blocks.
fn sha256_of_files(files: &[PathBuf]) -> Result<String, (PathBuf, std::io::Error)> {
    let mut hasher = Sha256::new();
    let mut block = vec![0u8; 1 << 20];
    for path in files {
        let fail = |e| (path.clone(), e);
        let mut file = std::fs::File::open(path).map_err(fail)?;
        loop {
            let n = file.read(&mut block).map_err(fail)?;
            if n == 0 {
                break;
            }
            hasher.update(&block[..n]);
        }
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

/// The run's inputs by file name, joined by " + ".
pub fn run_name(run: &railfuse_catalog::run::Run) -> String {
    run.inputs()
        .iter()
        .map(|i| file_name(&i.to_string_lossy()))
        .collect::<Vec<_>>()
        .join(" + ")
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
            sha256_of_files(&[p]).unwrap(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
