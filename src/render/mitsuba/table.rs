//! The loader's dispatch table: one row per plugin, naming the function in the plugin's own file
//! that reads its parameters. Every list of supported plugin names (error messages, the README)
//! comes from here.

use std::sync::Arc;

use super::props::Params;
use crate::error::Result;
use crate::render::bsdfs::{self, Bsdf};
use crate::render::emitters::{self, Emitter};
use crate::render::scene::GeometryDesc;
use crate::render::shapes;
use crate::render::textures::{self, Texture};

/// Reads a BSDF's parameters.
pub type BsdfLoader = fn(&mut Params) -> Result<Arc<dyn Bsdf>>;
/// Reads a texture's parameters.
pub type TextureLoader = fn(&mut Params) -> Result<Arc<dyn Texture>>;
/// Reads a top-level emitter's parameters.
pub type EmitterLoader = fn(&mut Params) -> Result<Arc<dyn Emitter>>;
/// Reads a shape's parameters into its geometry.
pub type ShapeLoader = fn(&mut Params) -> Result<GeometryDesc>;

/// `<bsdf type="...">`.
pub const BSDFS: &[(&str, BsdfLoader)] = &[
    ("bumpmap", bsdfs::bumpmap::load),
    ("conductor", bsdfs::conductor::load),
    ("dielectric", bsdfs::dielectric::load),
    ("diffuse", bsdfs::diffuse::load),
    ("mask", bsdfs::mask::load),
    ("plastic", bsdfs::plastic::load),
    ("roughconductor", bsdfs::roughconductor::load),
    ("roughdielectric", bsdfs::roughdielectric::load),
    ("roughplastic", bsdfs::roughplastic::load),
    ("thindielectric", bsdfs::thindielectric::load),
    ("twosided", bsdfs::twosided::load),
];

/// `<texture type="...">`.
pub const TEXTURES: &[(&str, TextureLoader)] = &[
    ("bitmap", textures::bitmap::load),
    ("checkerboard", textures::checkerboard::load),
];

/// Top-level `<emitter type="...">` (area emitters belong to shapes).
pub const EMITTERS: &[(&str, EmitterLoader)] = &[
    ("constant", emitters::constant::load),
    ("envmap", emitters::envmap::load),
    ("point", emitters::point::load),
];

/// `<shape type="...">`.
pub const SHAPES: &[(&str, ShapeLoader)] = &[
    ("cube", shapes::cube::load),
    ("disk", shapes::disk::load),
    ("obj", shapes::obj::load),
    ("rectangle", shapes::rectangle::load),
    ("sphere", shapes::sphere::load),
];

/// The names of a table's plugins, for messages and documentation.
pub fn names<T>(table: &[(&'static str, T)]) -> Vec<&'static str> {
    table.iter().map(|(name, _)| *name).collect()
}
