//! railfuse's protobuf messages: proto/railfuse/*.proto compiled by protox (a protobuf
//! compiler in Rust, so no protoc is needed) into a FileDescriptorSet, which the log writer
//! stores as each protobuf channel's schema, and into prost types.

use std::path::PathBuf;

use prost::Message;

fn main() {
    let files = ["railfuse/eddy_current.proto", "railfuse/fused.proto"];
    for f in files {
        println!("cargo:rerun-if-changed=proto/{f}");
    }
    let fds = protox::compile(files, ["proto"]).expect("proto/ compiles");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    std::fs::write(out.join("railfuse.fds"), fds.encode_to_vec()).expect("OUT_DIR is writable");
    prost_build::Config::new()
        .compile_fds(fds)
        .expect("prost-build generates the types");
}
