//! `symframe export gltf`: flags to an [`ExportConfig`], the library's glTF export, a summary.

use std::path::PathBuf;

use anyhow::Result;
use symframe_job::{export_gltf, ExportConfig};

use crate::cli::{ExportArgs, ExportFormat};

/// Runs the command; returns the files written.
pub fn run(args: &ExportArgs) -> Result<Vec<PathBuf>> {
    let ExportFormat::Gltf = args.format;
    let config = ExportConfig {
        input: args.input.clone(),
        output: args.output.clone(),
        mesh: args.mesh,
        depth: args.depth.clone(),
        max_jump: args.max_jump,
        camera: args.k.clone(),
    };
    let done = export_gltf(&config)?;
    if !crate::progress::chatty() {
        return Ok(done.written);
    }
    println!(
        "symframe export: {} ({} material{}, {} vertices, {} triangles): wrote {}",
        if args.mesh { "integrated mesh" } else { "quad" },
        if done.fitted {
            "fitted"
        } else {
            "estimated-frames"
        },
        if args.mesh {
            "; normals in the geometry"
        } else {
            ""
        },
        done.vertices,
        done.triangles,
        done.written
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(done.written)
}
