//! Loads the subset of Mitsuba's XML scene format that the renderer models into a [`SceneDesc`].
//!
//! The renderer is a reference for comparisons against Mitsuba, so a scene that loads but means
//! something slightly different from what Mitsuba would render is worse than one that does not
//! load at all. The loader is therefore strict: every element, plugin type and parameter outside
//! the subset below, every misspelt or unused parameter, every parameter given twice and every
//! value of the wrong kind is an [`Error::Scene`] naming the file, the line, the element and the
//! offending value. Where Mitsuba's default is something the renderer does not model (a gaussian
//! reconstruction filter), the scene must say otherwise or the user must override it.
//!
//! The subset, with Mitsuba 3's semantics and defaults:
//!
//! * `<scene version="3.x.y">` or `"2.x.y"`, and `"0.x.y"` (Mitsuba 0.5/0.6 files such as
//!   Bitterli's scenes) read as Mitsuba 3 upgrades them: camelCase parameter names become
//!   snake_case, `lookAt` becomes `lookat`, texture `uoffset`/`uscale`
//!   become `to_uv`;
//! * `<default name value>` and `$name` substitution in attribute values; `id` on top-level
//!   objects and `<ref id>` to a BSDF declared earlier;
//! * values `float`, `integer`, `boolean`, `string`, `rgb`, `point`, `vector` and `transform`
//!   (`translate`, `rotate`, `scale`, `matrix`, `lookat`, each left-multiplied); spectrum
//!   parameters also take a `float` (grey), and texturable ones a nested `<texture>`;
//! * the plugins of [`table`] (one row each, pointing at the plugin's own file);
//! * one `perspective` sensor (`sensor.rs`) with an `hdrfilm` (box filter, or any filter under
//!   [`LoadOptions::box_filter`]) and an `independent` sampler, and an optional `path`
//!   integrator;
//! * every world-space coordinate within ±[`MAX_COORDINATE`] (1e18), where the renderer's f32
//!   arithmetic cannot overflow.

mod props;
mod sensor;
pub mod table;

pub use props::Params;

use std::cell::Cell;
use std::collections::HashMap;
use std::marker::PhantomData;
use std::path::Path;
use std::sync::Arc;

use glam::{Mat3, Mat4, Vec3, Vec4};
use roxmltree::{Document, Node, NodeType};

use super::bsdfs::Bsdf;
use super::bsdfs::diffuse::Diffuse;
use super::emitters::Emitter;
use super::scene::{CameraDesc, GeometryDesc, IntegratorDesc, Rgb, SceneDesc, ShapeDesc};
use super::textures::Texture;
use crate::error::{Error, Num, Result};
use crate::limits::shorten;

/// What the command line may change about how a scene is read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LoadOptions {
    /// Render with a box reconstruction filter whatever the film asks for (`--rfilter box`);
    /// [`CameraDesc::replaced_filter`] records what it replaced.
    pub box_filter: bool,
}

/// Loads a Mitsuba 3 scene file; `obj` files it names are resolved relative to its folder.
///
/// Reading failures are [`Error::Io`]; everything the loader rejects is [`Error::Scene`].
pub fn load_file(path: &Path) -> Result<SceneDesc> {
    load_file_with(path, LoadOptions::default())
}

/// [`load_file`] with options from the command line.
pub fn load_file_with(path: &Path, options: LoadOptions) -> Result<SceneDesc> {
    let xml = std::fs::read_to_string(path).map_err(|err| Error::io(path.display(), &err))?;
    let base_dir = path.parent().unwrap_or_else(|| Path::new(""));
    load_counting(&xml, base_dir, &path.display().to_string(), options).0
}

/// Loads a Mitsuba 3 scene from its text; `obj` files are resolved relative to `base_dir` and
/// `source` is the file name used in error messages.
pub fn load_str(xml: &str, base_dir: &Path, source: &str) -> Result<SceneDesc> {
    load_counting(xml, base_dir, source, LoadOptions::default()).0
}

/// [`load_str`], also returning how many line numbers the load looked up (for a test: a
/// successful load looks up none).
fn load_counting(
    xml: &str,
    base_dir: &Path,
    source: &str,
    options: LoadOptions,
) -> (Result<SceneDesc>, usize) {
    let doc = match Document::parse(xml) {
        Ok(doc) => doc,
        Err(err) => {
            let err = Error::Scene {
                file: source.to_string(),
                line: err.pos().row,
                element: "xml".to_string(),
                message: format!("malformed XML: {err}"),
            };
            return (Err(err), 0);
        }
    };
    let mut loader = Loader {
        nodes: PhantomData,
        lines: LineIndex::new(xml),
        file: source,
        base_dir,
        defaults: HashMap::new(),
        bsdfs: HashMap::new(),
        ids: HashMap::new(),
        upgrade: false,
        box_override: options.box_filter,
    };
    let scene = loader.scene(doc.root_element());
    (scene, loader.lines.lookups.get())
}

/// Tags of value elements (Mitsuba's "properties"); every other child of a plugin is an object.
const VALUE_TAGS: &[&str] = &[
    "float",
    "integer",
    "boolean",
    "string",
    "rgb",
    "point",
    "vector",
    "transform",
];

/// Tags of nested objects that some plugin of the subset accepts.
const OBJECT_TAGS: &[&str] = &[
    "bsdf", "emitter", "ref", "film", "sampler", "rfilter", "texture",
];
/// Relative tolerance for "uniform scale" and "no scale" checks on transforms (f32 input).
pub(crate) const SIMILARITY_TOLERANCE: f32 = 1e-4;

/// Largest magnitude of any world-space coordinate of the scene (vertices, sphere and disk
/// extents, lights, the camera).
///
/// The renderer computes in f32. Its watertight triangle test multiplies two sheared coordinate
/// differences, each up to `4C` for coordinates within `±C`, and sums three such products twice
/// over: `96 C²` must stay below `f32::MAX ≈ 3.4e38`, so `C < 1.9e18`; squared distances
/// (`12 C²`) in light sampling and sphere tests fit as well. Beyond the limit a shape would be
/// missed or shaded with NaN, silently; so the loader refuses it, naming the value.
pub const MAX_COORDINATE: f32 = 1e18;

/// Longest attribute value that `$name` substitution may produce. Defaults may use earlier
/// defaults, so 64 doublings (`<default name="b" value="$a$a"/>`...) would otherwise ask for
/// 2^64 bytes.
const MAX_SUBSTITUTED_BYTES: usize = 1 << 16;

/// A value with the element it came from, so that range checks can point at that element.
pub(crate) type At<'a, 'i, T> = Option<(T, Node<'a, 'i>)>;

/// The value of an optional parameter, or its default.
pub(crate) fn value_or<T>(at: At<'_, '_, T>, default: T) -> T {
    at.map_or(default, |(value, _)| value)
}

/// How an element is named in messages: its tag and its `type` (or `name`, or `id`) attribute,
/// as written in the file.
pub(crate) fn describe(node: Node) -> String {
    let name = node.tag_name().name();
    let tag = shorten(name);
    let keys: &[&str] = if name == "ref" {
        &["id", "name"]
    } else {
        &["type", "name", "id"]
    };
    keys.iter()
        .find_map(|key| {
            node.attribute(*key)
                .map(|value| format!("{tag} {key}=\"{}\"", shorten(value)))
        })
        .unwrap_or(tag)
}

/// `a, b, c` for messages.
pub(crate) fn list(items: &[&str]) -> String {
    items.join(", ")
}

/// An f32 as messages print numbers ([`Num::from_f32`]).
pub(crate) fn num(x: f32) -> Num {
    Num::from_f32(x)
}

/// `(x, y, z)` with [`num`] components.
pub(crate) fn vec_text(v: Vec3) -> String {
    format!("({}, {}, {})", num(v.x), num(v.y), num(v.z))
}

/// A matrix row `x y z w` with [`num`] entries.
pub(crate) fn row_text(r: Vec4) -> String {
    format!("{} {} {} {}", num(r.x), num(r.y), num(r.z), num(r.w))
}

/// A 4x4 matrix, row by row, with [`num`] entries.
pub(crate) fn mat_text(m: Mat4) -> String {
    let rows: Vec<String> = (0..4).map(|i| row_text(m.row(i))).collect();
    format!("[{}]", rows.join("; "))
}

/// Byte offsets at which lines start, so that a node's line is a binary search.
///
/// roxmltree's own `Document::text_pos_at` counts newlines from the start of the file on each
/// call (its docs: "very expensive, use only for errors"). The loader used to call it for every
/// plugin it read, which made loading quadratic in the file size: 10,000 spheres loaded in
/// 1.2 s, 200,000 in 506 s. This index is built once in linear time and answers in
/// O(log lines); the loader never calls `text_pos_at` (a unit test checks the source).
struct LineIndex {
    /// Offset of the first byte of each line; `starts[0] = 0`.
    starts: Vec<usize>,
    /// Lookups made, so that a test can check that a successful load makes none.
    lookups: Cell<usize>,
}

impl LineIndex {
    fn new(text: &str) -> LineIndex {
        let starts = std::iter::once(0)
            .chain(
                text.bytes()
                    .enumerate()
                    .filter(|&(_, b)| b == b'\n')
                    .map(|(i, _)| i + 1),
            )
            .collect();
        LineIndex {
            starts,
            lookups: Cell::new(0),
        }
    }

    /// 1-based line of the byte at `offset` (as roxmltree counts: newlines before it, plus one).
    fn line(&self, offset: usize) -> u32 {
        self.lookups.set(self.lookups.get().saturating_add(1));
        let line = self.starts.partition_point(|&start| start <= offset);
        u32::try_from(line).unwrap_or(u32::MAX)
    }
}

/// Edit distance, to suggest the intended name of a misspelt parameter.
pub(crate) fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let substitution = diagonal + usize::from(ca != *cb);
            diagonal = row[j + 1];
            row[j + 1] = substitution.min(row[j] + 1).min(diagonal + 1);
        }
    }
    row[b.len()]
}

/// Loader state: line starts, `$` defaults and the ids declared so far. Declarations keep the
/// byte offset of their element; its line is looked up only for a message.
pub struct Loader<'a, 'i> {
    /// Ties the loader to the document whose nodes it reads (it keeps no reference to the
    /// document itself: line numbers come from `lines`).
    nodes: PhantomData<Node<'a, 'i>>,
    /// Line starts of the XML text.
    lines: LineIndex,
    /// File name for messages.
    file: &'a str,
    /// Folder against which `obj` file names are resolved.
    base_dir: &'a Path,
    /// `<default>` values by name, with the offset of the element that declared them.
    defaults: HashMap<String, (String, usize)>,
    /// Top-level BSDFs by id, for `<ref>`.
    bsdfs: HashMap<String, Arc<dyn Bsdf>>,
    /// Every declared id, with the element and offset that declared it.
    ids: HashMap<String, (String, usize)>,
    /// The file is older than Mitsuba 2 (`version="0.x"`): parameter names are upgraded from
    /// camelCase as Mitsuba 3 upgrades them.
    upgrade: bool,
    /// `--rfilter box`: any reconstruction filter is read as a box.
    box_override: bool,
}

impl<'a, 'i> Loader<'a, 'i> {
    /// 1-based line at which `node` starts.
    pub(crate) fn line(&self, node: Node) -> u32 {
        self.lines.line(node.range().start)
    }

    /// An [`Error::Scene`] about `node`.
    pub(crate) fn err(&self, node: Node, message: impl Into<String>) -> Error {
        Error::Scene {
            file: self.file.to_string(),
            line: self.line(node),
            element: describe(node),
            message: message.into(),
        }
    }

    /// The element children of `node`; comments are skipped and stray text is an error.
    pub(crate) fn elements(&self, node: Node<'a, 'i>) -> Result<Vec<Node<'a, 'i>>> {
        let mut out = Vec::new();
        for child in node.children() {
            match child.node_type() {
                NodeType::Element if child.tag_name().namespace().is_some() => {
                    return Err(self.err(child, "namespaced elements are not part of the format"));
                }
                NodeType::Element => out.push(child),
                NodeType::Text => {
                    let raw = child.text().unwrap_or("");
                    let text = raw.trim();
                    if !text.is_empty() {
                        // Report the line where the text starts, not where the whitespace does.
                        let start = child.range().start + (raw.len() - raw.trim_start().len());
                        return Err(Error::Scene {
                            file: self.file.to_string(),
                            line: self.lines.line(start),
                            element: describe(node),
                            message: format!("unexpected text {:?}", shorten(text)),
                        });
                    }
                }
                _ => {}
            }
        }
        Ok(out)
    }

    /// Fails if `node` has element children.
    pub(crate) fn leaf(&self, node: Node<'a, 'i>) -> Result<()> {
        match self.elements(node)?.first() {
            Some(child) => Err(self.err(
                *child,
                format!(
                    "unexpected element inside <{}> (line {}), which takes none",
                    describe(node),
                    self.line(node)
                ),
            )),
            None => Ok(()),
        }
    }

    /// Fails on any attribute not in `allowed`.
    pub(crate) fn check_attrs(&self, node: Node, allowed: &[&str]) -> Result<()> {
        for attr in node.attributes() {
            if attr.namespace().is_some() || !allowed.contains(&attr.name()) {
                let expected = if allowed.is_empty() {
                    "it takes none".to_string()
                } else {
                    format!("allowed: {}", list(allowed))
                };
                return Err(self.err(
                    node,
                    format!(
                        "unknown attribute {}=\"{}\"; {expected}",
                        shorten(attr.name()),
                        shorten(attr.value())
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Replaces each `$name` in an attribute value by its `<default>` value.
    fn substitute(&self, node: Node, attr: &str, raw: &str) -> Result<String> {
        let mut out = String::new();
        let mut rest = raw;
        while let Some(dollar) = rest.find('$') {
            out.push_str(&rest[..dollar]);
            let after = &rest[dollar + 1..];
            let len = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            let name = &after[..len];
            let raw_text = shorten(raw);
            if name.is_empty() {
                return Err(self.err(
                    node,
                    format!("{attr}=\"{raw_text}\": '$' is not followed by a parameter name"),
                ));
            }
            let Some((value, _)) = self.defaults.get(name) else {
                let name = shorten(name);
                return Err(self.err(
                    node,
                    format!(
                        "{attr}=\"{raw_text}\": undefined parameter ${name} \
                         (declare it earlier with <default name=\"{name}\" value=\"...\"/>)"
                    ),
                ));
            };
            let produced = out.len().saturating_add(value.len());
            if produced > MAX_SUBSTITUTED_BYTES {
                return Err(self.err(
                    node,
                    format!(
                        "{attr}=\"{raw_text}\": $ substitution produces more than \
                         {MAX_SUBSTITUTED_BYTES} bytes (defaults that expand into each other?)"
                    ),
                ));
            }
            out.push_str(value);
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(out)
    }

    /// An attribute after `$` substitution.
    pub(crate) fn attr(&self, node: Node, name: &str) -> Result<Option<String>> {
        node.attribute(name)
            .map(|raw| self.substitute(node, name, raw))
            .transpose()
    }

    /// A required attribute after `$` substitution.
    pub(crate) fn required_attr(&self, node: Node, name: &str) -> Result<String> {
        self.attr(node, name)?
            .ok_or_else(|| self.err(node, format!("missing attribute \"{name}\"")))
    }

    /// The `type` attribute of a plugin element, which must be one of `known`.
    fn plugin_type(&self, node: Node, kind: &str, known: &[&str]) -> Result<String> {
        let ty = self.required_attr(node, "type")?;
        if known.contains(&ty.as_str()) {
            Ok(ty)
        } else {
            Err(self.err(
                node,
                format!(
                    "unsupported {kind} type \"{}\"; supported: {}",
                    shorten(&ty),
                    list(known)
                ),
            ))
        }
    }

    /// Records the `id` attribute of a top-level object; ids must be unique.
    fn register_id(&mut self, node: Node) -> Result<Option<String>> {
        let Some(id) = self.attr(node, "id")? else {
            return Ok(None);
        };
        if id.is_empty() {
            return Err(self.err(node, "empty id"));
        }
        if let Some((element, offset)) = self.ids.get(&id) {
            return Err(self.err(
                node,
                format!(
                    "id \"{}\" is already used by <{element}> at line {}",
                    shorten(&id),
                    self.lines.line(*offset)
                ),
            ));
        }
        self.ids
            .insert(id.clone(), (describe(node), node.range().start));
        Ok(Some(id))
    }

    /// A finite number; the message names the attribute and its text.
    pub(crate) fn number(&self, node: Node, attr: &str, text: &str) -> Result<f32> {
        match text.trim().parse::<f32>() {
            Ok(value) if value.is_finite() => Ok(value),
            _ => Err(self.err(
                node,
                format!("{attr}=\"{}\" is not a finite number", shorten(text)),
            )),
        }
    }

    /// Numbers separated by commas and/or whitespace.
    pub(crate) fn numbers(&self, node: Node, attr: &str, text: &str) -> Result<Vec<f32>> {
        text.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|token| !token.is_empty())
            .map(|token| match token.parse::<f32>() {
                Ok(value) if value.is_finite() => Ok(value),
                _ => Err(self.err(
                    node,
                    format!(
                        "{attr}=\"{}\": \"{}\" is not a finite number",
                        shorten(text),
                        shorten(token)
                    ),
                )),
            })
            .collect()
    }

    /// Exactly three numbers.
    fn vec3(&self, node: Node, attr: &str, text: &str) -> Result<Vec3> {
        match self.numbers(node, attr, text)?.as_slice() {
            [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
            other => Err(self.err(
                node,
                format!(
                    "{attr}=\"{}\" must hold 3 numbers, found {}",
                    shorten(text),
                    other.len()
                ),
            )),
        }
    }

    /// A vector given as `value="x, y, z"` or as `x`, `y`, `z` attributes (each defaulting to
    /// `default`), not both.
    pub(crate) fn xyz(&self, node: Node, default: f32) -> Result<Vec3> {
        let components = [
            self.attr(node, "x")?,
            self.attr(node, "y")?,
            self.attr(node, "z")?,
        ];
        if let Some(value) = self.attr(node, "value")? {
            if components.iter().any(Option::is_some) {
                return Err(self.err(
                    node,
                    format!(
                        "value=\"{}\" given together with x/y/z; use one or the other",
                        shorten(&value)
                    ),
                ));
            }
            return self.vec3(node, "value", &value);
        }
        let mut out = Vec3::splat(default);
        for (i, (key, text)) in ["x", "y", "z"].iter().zip(&components).enumerate() {
            if let Some(text) = text {
                out[i] = self.number(node, key, text)?;
            }
        }
        Ok(out)
    }

    /// A `<transform>`: its operations in document order, each left-multiplied (`T = op·T`).
    pub(crate) fn transform(&self, node: Node<'a, 'i>) -> Result<Mat4> {
        let mut total = Mat4::IDENTITY;
        for op in self.elements(node)? {
            self.leaf(op)?;
            let matrix = match op.tag_name().name() {
                "translate" => {
                    self.check_attrs(op, &["x", "y", "z", "value"])?;
                    Mat4::from_translation(self.xyz(op, 0.0)?)
                }
                "rotate" => {
                    self.check_attrs(op, &["x", "y", "z", "value", "angle"])?;
                    let axis = self.xyz(op, 0.0)?;
                    let angle_text = self.required_attr(op, "angle")?;
                    let angle = self.number(op, "angle", &angle_text)?;
                    // Mitsuba rejects a zero axis ("rotation axis cannot be zero").
                    if axis == Vec3::ZERO {
                        return Err(
                            self.err(op, format!("rotation axis {} is zero", vec_text(axis)))
                        );
                    }
                    // Mitsuba 3 (Dr.Jit's `rotate`) uses the axis `a` as given, without
                    // normalising it: M = cos·I + (1 − cos)·a·aᵀ + sin·[a]×. For a non-unit
                    // axis that is not a pure rotation, but it is what Mitsuba renders. Its
                    // XML parser evaluates it in double precision and rounds to float.
                    let [x, y, z] = axis.to_array().map(f64::from);
                    let (s, c) = f64::from(angle).to_radians().sin_cos();
                    let k = 1.0 - c;
                    // Row-major; glam takes columns, hence the transpose.
                    let rows = [
                        [x * x * k + c, x * y * k - z * s, x * z * k + y * s],
                        [y * x * k + z * s, y * y * k + c, y * z * k - x * s],
                        [z * x * k - y * s, z * y * k + x * s, z * z * k + c],
                    ];
                    let rows = rows.map(|row| row.map(|v| v as f32));
                    Mat4::from_mat3(Mat3::from_cols_array_2d(&rows).transpose())
                }
                "scale" => {
                    self.check_attrs(op, &["x", "y", "z", "value"])?;
                    Mat4::from_scale(self.scale_factors(op)?)
                }
                "matrix" => {
                    self.check_attrs(op, &["value"])?;
                    let text = self.required_attr(op, "value")?;
                    let values = self.numbers(op, "value", &text)?;
                    let Ok(rows) = <[f32; 16]>::try_from(values.as_slice()) else {
                        return Err(self.err(
                            op,
                            format!(
                                "value=\"{}\" must hold 16 numbers (row-major 4x4), found {}",
                                shorten(&text),
                                values.len()
                            ),
                        ));
                    };
                    // glam reads column-major, so row-major input arrives transposed.
                    Mat4::from_cols_array(&rows).transpose()
                }
                "lookat" | "lookAt" if op.tag_name().name() == "lookat" || self.upgrade => {
                    self.check_attrs(op, &["origin", "target", "up"])?;
                    self.look_at(op)?
                }
                other => {
                    return Err(self.err(
                        op,
                        format!(
                            "unsupported transform operation <{}> in <{}> (line {}); \
                             supported: translate, rotate, scale, matrix, lookat",
                            shorten(other),
                            describe(node),
                            self.line(node)
                        ),
                    ));
                }
            };
            total = matrix * total;
        }
        if !total.is_finite() {
            return Err(self.err(
                node,
                format!("the transform is not finite: {}", mat_text(total)),
            ));
        }
        Ok(total)
    }

    /// The factors of a `<scale>`: `value="s"` (uniform), `value="x y z"`, or `x`/`y`/`z`
    /// attributes each defaulting to 1.
    fn scale_factors(&self, op: Node) -> Result<Vec3> {
        let factors = match self.attr(op, "value")? {
            None => self.xyz(op, 1.0)?,
            Some(text) => {
                if let Some(key) = ["x", "y", "z"].iter().find(|k| op.attribute(**k).is_some()) {
                    return Err(self.err(
                        op,
                        format!(
                            "value=\"{}\" given together with {key}; use one \
                             or the other",
                            shorten(&text)
                        ),
                    ));
                }
                match self.numbers(op, "value", &text)?.as_slice() {
                    [s] => Vec3::splat(*s),
                    [x, y, z] => Vec3::new(*x, *y, *z),
                    other => {
                        return Err(self.err(
                            op,
                            format!(
                                "value=\"{}\" must hold 1 (uniform) or 3 \
                                 numbers, found {}",
                                shorten(&text),
                                other.len()
                            ),
                        ));
                    }
                }
            }
        };
        Ok(factors)
    }

    /// Mitsuba's look-at frame: columns `left = normalize(up × dir)`, `dir × left`, `dir`,
    /// `origin`, so local `+z` looks at the target and local `+x` is image-left.
    fn look_at(&self, op: Node) -> Result<Mat4> {
        let mut points = [Vec3::ZERO; 3];
        for (point, key) in points.iter_mut().zip(["origin", "target", "up"]) {
            let text = self.required_attr(op, key)?;
            *point = self.vec3(op, key, &text)?;
        }
        let [origin, target, up] = points;
        let Some(dir) = (target - origin).try_normalize() else {
            return Err(self.err(
                op,
                format!(
                    "origin {} and target {} coincide",
                    vec_text(origin),
                    vec_text(target)
                ),
            ));
        };
        let left = up.cross(dir);
        if !(left.length() > 1e-6 * up.length()) {
            return Err(self.err(
                op,
                format!(
                    "up {} is zero or parallel to the viewing direction {}",
                    vec_text(up),
                    vec_text(dir)
                ),
            ));
        }
        let left = left.normalize();
        let new_up = dir.cross(left);
        Ok(Mat4::from_cols(
            left.extend(0.0),
            new_up.extend(0.0),
            dir.extend(0.0),
            origin.extend(1.0),
        ))
    }

    /// An optional `to_world`, which must be an invertible affine map (identity if absent).
    pub(crate) fn affine(&self, to_world: At<'a, 'i, Mat4>) -> Result<Mat4> {
        let Some((matrix, node)) = to_world else {
            return Ok(Mat4::IDENTITY);
        };
        if matrix.row(3) != Vec4::W {
            return Err(self.err(
                node,
                format!(
                    "a projective transform (bottom row {}) is not supported here",
                    row_text(matrix.row(3))
                ),
            ));
        }
        let det = Mat3::from_mat4(matrix).determinant();
        if !(det.abs() > 0.0) {
            return Err(self.err(
                node,
                format!(
                    "the transform is singular (determinant {}): {}",
                    num(det),
                    mat_text(matrix)
                ),
            ));
        }
        Ok(matrix)
    }

    /// The `<scene>` root.
    fn scene(&mut self, root: Node<'a, 'i>) -> Result<SceneDesc> {
        if root.tag_name().name() != "scene" || root.tag_name().namespace().is_some() {
            return Err(self.err(root, "the root element must be <scene version=\"3.x.y\">"));
        }
        self.check_attrs(root, &["version"])?;
        let Some(version) = root.attribute("version") else {
            return Err(self.err(root, "missing attribute \"version\" (e.g. \"3.0.0\")"));
        };
        let parts: Vec<&str> = version.split('.').collect();
        let major = match parts.as_slice() {
            [major, _, _] if parts.iter().all(|p| p.parse::<u32>().is_ok()) => major.parse().ok(),
            _ => None,
        };
        match major {
            Some(0 | 2 | 3) => {}
            _ => {
                return Err(self.err(
                    root,
                    format!(
                        "version=\"{}\" is not a Mitsuba scene version this loader reads \
                         (0.x.y, 2.x.y or 3.x.y)",
                        shorten(version)
                    ),
                ));
            }
        }
        // Mitsuba 3 reads files older than 2.0 after renaming parameters from camelCase.
        self.upgrade = major == Some(0);

        let mut integrator: At<'a, 'i, IntegratorDesc> = None;
        let mut sensor: At<'a, 'i, CameraDesc> = None;
        let mut shapes = Vec::new();
        let mut emitters: Vec<(Arc<dyn Emitter>, Node<'a, 'i>)> = Vec::new();
        for child in self.elements(root)? {
            match child.tag_name().name() {
                "default" => self.default(child)?,
                "integrator" => {
                    if let Some((_, first)) = integrator {
                        return Err(self.err(
                            child,
                            format!(
                                "a second <integrator> (the first is at line {})",
                                self.line(first)
                            ),
                        ));
                    }
                    integrator = Some((self.integrator(child)?, child));
                }
                "sensor" => {
                    if let Some((_, first)) = sensor {
                        return Err(self.err(
                            child,
                            format!(
                                "a second <sensor>: exactly one is supported (the first is at \
                                 line {})",
                                self.line(first)
                            ),
                        ));
                    }
                    sensor = Some((self.sensor(child)?, child));
                }
                "shape" => shapes.push(self.shape(child)?),
                "bsdf" => self.top_bsdf(child)?,
                "emitter" => {
                    let emitter = self.emitter(child)?;
                    if emitter.is_infinite() {
                        if let Some((_, first)) = emitters.iter().find(|(e, _)| e.is_infinite()) {
                            return Err(self.err(
                                child,
                                format!(
                                    "a second emitter at infinity (constant or envmap): Mitsuba \
                                     allows one (the first is at line {})",
                                    self.line(*first)
                                ),
                            ));
                        }
                    }
                    emitters.push((emitter, child));
                }
                other => {
                    return Err(self.err(
                        child,
                        format!(
                            "unsupported element <{}> in <scene>; supported: default, \
                             integrator, sensor, shape, bsdf, emitter",
                            shorten(other)
                        ),
                    ));
                }
            }
        }
        let Some((camera, _)) = sensor else {
            return Err(self.err(root, "the scene has no <sensor type=\"perspective\">"));
        };
        Ok(SceneDesc {
            integrator: value_or(integrator, IntegratorDesc::default()),
            camera,
            shapes,
            emitters: emitters.into_iter().map(|(e, _)| e).collect(),
        })
    }

    /// `<default name value>`: declares `$name` for the attributes that follow.
    fn default(&mut self, node: Node<'a, 'i>) -> Result<()> {
        self.check_attrs(node, &["name", "value"])?;
        self.leaf(node)?;
        let Some(name) = node.attribute("name") else {
            return Err(self.err(node, "missing attribute \"name\""));
        };
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(self.err(
                node,
                format!(
                    "name=\"{}\" is not a parameter name (letters, digits, '_')",
                    shorten(name)
                ),
            ));
        }
        let value = self.required_attr(node, "value")?;
        if let Some((_, offset)) = self.defaults.get(name) {
            return Err(self.err(
                node,
                format!(
                    "a second default for ${} (the first is at line {})",
                    shorten(name),
                    self.lines.line(*offset)
                ),
            ));
        }
        self.defaults
            .insert(name.to_string(), (value, node.range().start));
        Ok(())
    }

    /// Whether the file predates Mitsuba 2, so that old parameter names are upgraded.
    pub(crate) fn upgrades_names(&self) -> bool {
        self.upgrade
    }

    /// The folder against which file names in the scene are resolved.
    pub(crate) fn base_dir(&self) -> &Path {
        self.base_dir
    }

    /// A parameter name as Mitsuba 3 reads it: in files older than 2.0, camelCase becomes
    /// snake_case (`toWorld` -> `to_world`, `intIOR` -> `int_ior`): an underscore goes before an
    /// upper-case letter that follows a lower-case one, and that run of capitals is lowered.
    pub(crate) fn param_name(&self, name: &str) -> String {
        if !self.upgrade {
            return name.to_string();
        }
        let mut out = String::with_capacity(name.len() + 4);
        let mut prev_lower = false;
        let mut in_run = false;
        for c in name.chars() {
            if c.is_ascii_uppercase() && (prev_lower || in_run) {
                if prev_lower {
                    out.push('_');
                }
                out.push(c.to_ascii_lowercase());
                in_run = true;
            } else {
                out.push(c);
                in_run = false;
            }
            prev_lower = c.is_ascii_lowercase();
        }
        out
    }

    /// The loader of plugin `type` in `table`, or an error listing the supported ones.
    fn dispatch<T: Copy>(&self, node: Node, kind: &str, table: &[(&'static str, T)]) -> Result<T> {
        let ty = self.required_attr(node, "type")?;
        match table.iter().find(|(name, _)| *name == ty) {
            Some((_, load)) => Ok(*load),
            None => Err(self.err(
                node,
                format!(
                    "unsupported {kind} type \"{}\"; supported: {}",
                    shorten(&ty),
                    list(&table::names(table))
                ),
            )),
        }
    }

    /// Reads a plugin element with its loader: its parameters, then a check that every one was
    /// used.
    fn read_plugin<T>(&self, node: Node<'a, 'i>, load: fn(&mut Params) -> Result<T>) -> Result<T> {
        let mut params = Params::collect(self, node)?;
        let value = load(&mut params)?;
        params.finish()?;
        Ok(value)
    }

    /// A top-level `<bsdf>`, which must carry an id.
    fn top_bsdf(&mut self, node: Node<'a, 'i>) -> Result<()> {
        self.check_attrs(node, &["type", "id"])?;
        if node.attribute("id").is_none() {
            return Err(self.err(
                node,
                "a top-level <bsdf> needs an id so that shapes can <ref> it",
            ));
        }
        let bsdf = self.bsdf(node)?;
        let id = self.register_id(node)?.expect("checked above");
        self.bsdfs.insert(id, bsdf);
        Ok(())
    }

    /// A BSDF nested in a shape or another BSDF: a `<bsdf>` or a `<ref>` to a top-level one.
    pub(crate) fn nested_bsdf(&self, node: Node<'a, 'i>) -> Result<Arc<dyn Bsdf>> {
        if node.tag_name().name() != "ref" {
            self.check_attrs(node, &["type", "name"])?;
            return self.bsdf(node);
        }
        self.check_attrs(node, &["id", "name"])?;
        self.leaf(node)?;
        let id = self.required_attr(node, "id")?;
        if let Some(bsdf) = self.bsdfs.get(&id) {
            return Ok(bsdf.clone());
        }
        if let Some((element, offset)) = self.ids.get(&id) {
            return Err(self.err(
                node,
                format!(
                    "id \"{}\" refers to <{element}> at line {}, not to a bsdf",
                    shorten(&id),
                    self.lines.line(*offset)
                ),
            ));
        }
        let mut known: Vec<&str> = self.bsdfs.keys().map(String::as_str).collect();
        known.sort_unstable();
        // A scene may declare thousands: name a few.
        const SHOWN: usize = 20;
        let more = known.len().saturating_sub(SHOWN);
        known.truncate(SHOWN);
        let known = match (known.is_empty(), more) {
            (true, _) => "none".to_string(),
            (false, 0) => list(&known),
            (false, more) => format!("{} and {more} more", list(&known)),
        };
        let id = shorten(&id);
        Err(self.err(
            node,
            format!("unknown id \"{id}\"; bsdfs declared so far: {known}"),
        ))
    }

    /// The body of a `<bsdf>` element (attributes already checked by the caller).
    fn bsdf(&self, node: Node<'a, 'i>) -> Result<Arc<dyn Bsdf>> {
        let load = self.dispatch(node, "bsdf", table::BSDFS)?;
        self.read_plugin(node, load)
    }

    /// A `<texture>` nested in a plugin.
    pub(crate) fn texture(&self, node: Node<'a, 'i>) -> Result<Arc<dyn Texture>> {
        self.check_attrs(node, &["type", "name"])?;
        let load = self.dispatch(node, "texture", table::TEXTURES)?;
        self.read_plugin(node, load)
    }

    /// A top-level `<emitter>`.
    fn emitter(&mut self, node: Node<'a, 'i>) -> Result<Arc<dyn Emitter>> {
        self.check_attrs(node, &["type", "id"])?;
        if node.attribute("type") == Some("area") {
            return Err(self.err(node, "an area emitter must be nested inside a <shape>"));
        }
        let load = self.dispatch(node, "emitter", table::EMITTERS)?;
        self.register_id(node)?;
        self.read_plugin(node, load)
    }

    /// A `<shape>` with its BSDF and optional area emitter.
    fn shape(&mut self, node: Node<'a, 'i>) -> Result<ShapeDesc> {
        self.check_attrs(node, &["type", "id"])?;
        let load = self.dispatch(node, "shape", table::SHAPES)?;
        self.register_id(node)?;
        let mut params = Params::collect(self, node)?;
        let bsdfs = params.objects(&["bsdf", "ref"]);
        let emitters = params.objects(&["emitter"]);
        params.reject(
            "flip_normals",
            "Mitsuba's flip_normals is not modelled; orient the shape with to_world",
        )?;
        let geometry = load(&mut params)?;
        params.finish()?;
        self.check_reach(node, &geometry)?;

        let bsdf: Arc<dyn Bsdf> = match bsdfs.as_slice() {
            // Mitsuba's default BSDF is diffuse of reflectance 0.5, but black on a shape with an
            // emitter (its `Shape` constructor): a light without a BSDF reflects nothing.
            [] if !emitters.is_empty() => Arc::new(Diffuse::new(Rgb::ZERO)),
            [] => Arc::new(Diffuse::new(Rgb::splat(0.5))),
            [bsdf] => {
                let loaded = self.nested_bsdf(*bsdf)?;
                let has_uvs = matches!(&geometry, GeometryDesc::Mesh(m) if m.uvs.is_some());
                if loaded.uses_uv() && !has_uvs {
                    return Err(self.err(
                        *bsdf,
                        "this bsdf has a texture, but the shape has no texture coordinates \
                         (only rectangles, cubes and OBJ meshes with vt lines have them here)",
                    ));
                }
                loaded
            }
            [first, second, ..] => {
                return Err(self.err(
                    *second,
                    format!(
                        "a shape takes at most one bsdf (the first is at line {})",
                        self.line(*first)
                    ),
                ));
            }
        };
        let emission = match emitters.as_slice() {
            [] => None,
            [emitter] => Some(self.area_emitter(*emitter)?),
            [first, second, ..] => {
                return Err(self.err(
                    *second,
                    format!(
                        "a shape takes at most one emitter (the first is at line {})",
                        self.line(*first)
                    ),
                ));
            }
        };
        Ok(ShapeDesc {
            geometry,
            bsdf,
            emission,
        })
    }

    /// An `<emitter type="area">` nested in a shape; returns its radiance.
    fn area_emitter(&self, node: Node<'a, 'i>) -> Result<Rgb> {
        self.check_attrs(node, &["type", "name"])?;
        let ty = self.required_attr(node, "type")?;
        if ty != "area" {
            return Err(self.err(
                node,
                format!(
                    "only area emitters may be nested in a shape, not \"{}\"",
                    shorten(&ty)
                ),
            ));
        }
        self.read_plugin(node, super::emitters::area::load)
    }

    /// Fails if any point of `geometry` lies beyond [`MAX_COORDINATE`] (OBJ meshes were
    /// checked with their lines already).
    fn check_reach(&self, node: Node, geometry: &GeometryDesc) -> Result<()> {
        let (what, reach) = match geometry {
            GeometryDesc::Mesh(mesh) => match first_beyond_limit(&mesh.positions) {
                Some((i, reach)) => (format!("vertex {}", vec_text(mesh.positions[i])), reach),
                None => return Ok(()),
            },
            &GeometryDesc::Sphere { center, radius } => {
                match beyond_limit(center.abs() + Vec3::splat(radius)) {
                    Some(reach) => (
                        format!(
                            "the sphere of centre {} and radius {}",
                            vec_text(center),
                            num(radius)
                        ),
                        reach,
                    ),
                    None => return Ok(()),
                }
            }
            GeometryDesc::Disk { to_world } => {
                let c = to_world.w_axis.truncate();
                let (a, b) = (to_world.x_axis.truncate(), to_world.y_axis.truncate());
                // Extent of c + x·a + y·b over the unit disk, per axis: sqrt(a_i² + b_i²).
                match beyond_limit(c.abs() + (a * a + b * b).sqrt()) {
                    Some(reach) => (format!("the disk of centre {}", vec_text(c)), reach),
                    None => return Ok(()),
                }
            }
        };
        Err(self.err(node, beyond_message(&what, reach)))
    }
}

/// The message for `what` reaching `reach`, beyond [`MAX_COORDINATE`].
pub(crate) fn beyond_message(what: &str, reach: f32) -> String {
    format!(
        "{what} reaches {} after to_world, beyond the renderer's coordinate limit of ±{} (its \
         f32 arithmetic would overflow and the shape would silently vanish)",
        num(reach),
        num(MAX_COORDINATE)
    )
}

/// The largest coordinate magnitude of `p`, if `p` is not finite or exceeds
/// [`MAX_COORDINATE`].
pub(crate) fn beyond_limit(p: Vec3) -> Option<f32> {
    let reach = p.abs().max_element();
    (!(p.is_finite() && reach <= MAX_COORDINATE)).then_some(reach)
}

/// The first point beyond [`MAX_COORDINATE`], with its largest coordinate magnitude.
pub(crate) fn first_beyond_limit(points: &[Vec3]) -> Option<(usize, f32)> {
    points
        .iter()
        .enumerate()
        .find_map(|(i, &p)| beyond_limit(p).map(|reach| (i, reach)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene of `n` groups of shapes, each group with ids, `$` defaults, a `<ref>` and every
    /// shape type, emitter and BSDF that needs no file: the paths a successful load takes.
    fn many_shapes(n: usize) -> String {
        let mut xml = String::from(
            r#"<scene version="3.0.0">
    <default name="r" value="0.25"/>
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective" id="cam">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/><rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
    </sensor>
    <bsdf type="twosided" id="grey"><bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></bsdf>
    <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    <emitter type="point"><rgb name="intensity" value="1"/><point name="position" x="0" y="3" z="0"/></emitter>
"#,
        );
        for i in 0..n {
            xml.push_str(&format!(
                r#"    <shape type="sphere" id="s{i}"><point name="center" x="{i}" y="0" z="0"/><float name="radius" value="$r"/><ref id="grey"/></shape>
    <shape type="cube" id="c{i}"><transform name="to_world"><scale value="0.1"/><translate x="{i}" y="1"/></transform><bsdf type="roughconductor"><string name="distribution" value="ggx"/></bsdf></shape>
    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="2"/></emitter></shape>
    <shape type="disk"><bsdf type="dielectric"/></shape>
"#
            ));
        }
        xml.push_str("</scene>\n");
        xml
    }

    /// Loading was quadratic because every plugin looked up its own line (by a scan from the
    /// start of the file) to prepare messages it would not send. Whatever its size, a scene
    /// that loads must look up no line at all; and one that fails looks up a few, so the
    /// counter is live. Not a timing test: it counts.
    #[test]
    fn a_successful_load_looks_up_no_line() {
        let xml = many_shapes(500);
        let (scene, lookups) =
            load_counting(&xml, Path::new("."), "many.xml", LoadOptions::default());
        assert_eq!(scene.expect("loads").shapes.len(), 2000);
        assert_eq!(lookups, 0);

        let bad = xml.replacen("</scene>", "<shape type=\"sphere\" id=\"s7\"/></scene>", 1);
        let (scene, lookups) =
            load_counting(&bad, Path::new("."), "many.xml", LoadOptions::default());
        let err = scene.expect_err("a duplicate id").to_string();
        assert!(
            err.contains("already used by <shape type=\"sphere\"> at line 41"),
            "{err}"
        );
        assert!(
            (1..=4).contains(&lookups),
            "{lookups} lookups for one error"
        );
    }

    /// The other half of the guard above: nothing in the loader calls roxmltree's
    /// `Document::text_pos_at`, which scans from the start of the file on every call.
    #[test]
    fn the_loader_never_scans_the_document_for_lines() {
        for source in [
            include_str!("mod.rs"),
            include_str!("props.rs"),
            include_str!("sensor.rs"),
        ] {
            let code = &source[..source.find("#[cfg(test)]").unwrap_or(source.len())];
            assert!(!code.contains(concat!("text_pos", "_at(")));
        }
    }

    /// The index counts lines exactly as roxmltree does, at every offset, with `\r\n` line
    /// ends, multi-byte characters and no final newline.
    #[test]
    fn line_index_agrees_with_roxmltree() {
        let text =
            "<scene version=\"3.0.0\">\r\n<!-- é ü 漢 -->\n\n<shape type=\"cube\"/>\n</scene>";
        let doc = Document::parse(text).unwrap();
        let index = LineIndex::new(text);
        // roxmltree's column count panics inside a multi-byte character; nodes never start there.
        let boundaries = (0..=text.len() + 2).filter(|&i| text.is_char_boundary(i.min(text.len())));
        for offset in boundaries {
            assert_eq!(
                index.line(offset),
                doc.text_pos_at(offset).row,
                "offset {offset}"
            );
        }
    }

    #[test]
    fn numbers_in_messages_are_short() {
        assert_eq!(num(3e38).to_string(), "3e38");
        assert_eq!(num(0.1).to_string(), "0.1");
        assert_eq!(num(-2.5).to_string(), "-2.5");
        assert_eq!(vec_text(Vec3::new(1e20, 0.5, -0.0)), "(1e20, 0.5, -0)");
    }
}
