//! railfuse's protobuf messages: proto/railfuse/*.proto compiled by protox (a protobuf
//! compiler in Rust, so no protoc is needed) into a FileDescriptorSet, which the log writer
//! stores as each protobuf channel's schema, and into prost types. The same for the Foxglove
//! schemas railfuse writes its twins in (proto/foxglove/), in a set of their own.

use std::path::PathBuf;

use prost::Message;

fn main() {
    println!("cargo:rerun-if-changed=proto");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    for package in ["railfuse", "foxglove"] {
        let files = proto_files(package);
        let fds = protox::compile(&files, ["proto"]).expect("proto/ compiles");
        let set = out.join(format!("{package}.fds"));
        std::fs::write(set, fds.encode_to_vec()).expect("OUT_DIR is writable");
        prost_build::Config::new()
            .btree_map([
                ".railfuse.SourceStats.skipped",
                ".railfuse.SourceStats.warnings",
            ])
            .compile_fds(fds)
            .expect("prost-build generates the types");
    }
}

/// The .proto files of `package`, sorted, so the descriptors (and every log's schema bytes)
/// do not depend on the order the file system lists them in.
fn proto_files(package: &str) -> Vec<String> {
    let dir = format!("proto/{package}");
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .expect("the proto directory exists")
        .map(|e| e.expect("the proto directory is readable").file_name())
        .filter_map(|n| n.into_string().ok())
        .filter(|n| n.ends_with(".proto"))
        .map(|n| format!("{package}/{n}"))
        .collect();
    files.sort();
    for f in &files {
        println!("cargo:rerun-if-changed=proto/{f}");
    }
    files
}
