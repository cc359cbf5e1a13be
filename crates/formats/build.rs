//! Compiles the workspace's `proto/` without a system `protoc`: protox parses the files into
//! a `FileDescriptorSet`, tonic-prost-build generates the code, and the
//! encoded set is written to `OUT_DIR` for gRPC server reflection.
//!
//! Two passes. The first generates every message and the client. The second
//! generates only the server trait, with `inbetween.v1.Frame` mapped to
//! `crate::wire::frame::WireFrame`: a frame the streaming engine has already
//! encoded once for all its viewers, so a tick is encoded once however many
//! gRPC clients watch it (the client side still decodes a plain `Frame`).

use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=../../proto");
    let out = PathBuf::from(std::env::var("OUT_DIR")?);

    let mut compiler = protox::Compiler::new(["../../proto"])?;
    compiler.include_source_info(true).open_file("inbetween/v1/animation.proto")?;
    let set = compiler.file_descriptor_set();
    std::fs::write(out.join("inbetween_descriptor.bin"), compiler.encode_file_descriptor_set())?;

    tonic_prost_build::configure().build_server(false).build_client(true).compile_fds(set.clone())?;

    let server_dir = out.join("server");
    std::fs::create_dir_all(&server_dir)?;
    let mut services_only = set;
    for file in &mut services_only.file {
        file.message_type.clear();
        file.enum_type.clear();
    }
    tonic_prost_build::configure()
        .build_server(true)
        .build_client(false)
        .out_dir(&server_dir)
        .extern_path(".inbetween.v1", "crate::wire::proto::pb")
        .extern_path(".inbetween.v1.Frame", "crate::wire::frame::WireFrame")
        .compile_fds(services_only)?;
    Ok(())
}
