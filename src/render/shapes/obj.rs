//! Mitsuba's `obj` shape: one world-space mesh from a Wavefront OBJ file, read by
//! [`super::obj_file`] (Mitsuba's semantics: one mesh per file, vertices split per `v/vt/vn`
//! triple, fan triangulation, `v` of texture coordinates flipped). Vertex normals from the file
//! are kept unless `face_normals`; without them Mitsuba computes angle-weighted vertex normals,
//! and so does this loader. Errors inside the file name the OBJ file and its line.

use super::mesh::{angle_weighted_normals, transform_mesh};
use super::obj_file;
use crate::error::Result;
use crate::render::mitsuba::{Params, beyond_message, first_beyond_limit, vec_text};
use crate::render::scene::{GeometryDesc, MeshDesc};
use glam::Mat4;
use roxmltree::Node;

/// Reads `<shape type="obj">`: `filename` (relative to the scene's folder), `face_normals`,
/// `to_world`.
pub fn load(p: &mut Params) -> Result<GeometryDesc> {
    let filename = p.string("filename")?;
    let face_normals = p.boolean("face_normals")?;
    let to_world = p.transform("to_world")?;
    p.finish()?;
    let Some((filename, at)) = filename else {
        return Err(p.err(
            None,
            "missing required parameter <string name=\"filename\">",
        ));
    };
    let to_world = p.loader().affine(to_world)?;
    let face_normals = face_normals.is_some_and(|(f, _)| f);
    Ok(GeometryDesc::Mesh(read(
        p,
        at,
        &filename,
        face_normals,
        to_world,
    )?))
}

/// Loads the file; `at` is the `filename` element, named in errors.
fn read(
    p: &Params,
    at: Node,
    filename: &str,
    face_normals: bool,
    to_world: Mat4,
) -> Result<MeshDesc> {
    let path = p.loader().base_dir().join(filename);
    let bytes = std::fs::read(&path).map_err(|err| {
        p.loader().err(
            at,
            format!("cannot read OBJ file {}: {err}", path.display()),
        )
    })?;
    // Materials (mtllib, usemtl) are ignored: the shape's BSDF comes from the scene file.
    let parsed = obj_file::parse(&bytes).map_err(|err| {
        p.loader().err(
            at,
            format!(
                "OBJ file {}, line {}: {}",
                path.display(),
                err.line,
                err.message
            ),
        )
    })?;
    if parsed.indices.is_empty() {
        return Err(p.loader().err(
            at,
            format!("OBJ file {} contains no triangles", path.display()),
        ));
    }
    let file_normals = if face_normals { None } else { parsed.normals };
    let mut mesh = transform_mesh(
        parsed.positions,
        file_normals,
        parsed.uvs,
        parsed.indices,
        to_world,
    );
    if let Some((i, reach)) = first_beyond_limit(&mesh.positions) {
        let what = format!(
            "OBJ file {}, line {}: vertex {}",
            path.display(),
            parsed.lines[i],
            vec_text(mesh.positions[i])
        );
        return Err(p.err(None, beyond_message(&what, reach)));
    }
    if !face_normals && mesh.normals.is_none() {
        mesh.normals = Some(angle_weighted_normals(&mesh.positions, &mesh.indices));
    }
    Ok(mesh)
}
