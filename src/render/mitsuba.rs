//! Loads the subset of Mitsuba 3's XML scene format that the renderer models into a [`SceneDesc`].
//!
//! The renderer is a reference for comparisons against Mitsuba, so a scene that loads but means
//! something slightly different from what Mitsuba would render is worse than one that does not
//! load at all. The loader is therefore strict: every element, plugin type and parameter outside
//! the subset below, every misspelt or unused parameter, every parameter given twice and every
//! value of the wrong kind is an [`Error::Scene`] naming the file, the line, the element and the
//! offending value. Where Mitsuba's default is something the renderer does not model (a gaussian
//! reconstruction filter, a Beckmann microfacet distribution), the parameter must be given
//! explicitly.
//!
//! The subset, with Mitsuba 3's semantics and defaults:
//!
//! * `<scene version="3.x.y">` with `<default name value>` and `$name` substitution in attribute
//!   values; `id` on top-level objects and `<ref id>` to a BSDF declared earlier;
//! * values `float`, `integer`, `boolean`, `string`, `rgb`, `point`, `vector` and
//!   `transform` (`translate`, `rotate`, `scale`, `matrix`, `lookat`, each left-multiplied);
//!   spectrum parameters also take a `float` (grey);
//! * shapes `rectangle`, `cube`, `sphere`, `disk`, `obj`, each with at most one BSDF and one
//!   `area` emitter;
//! * BSDFs `diffuse`, `conductor` and `roughconductor` (`material="none"` only, GGX only),
//!   `dielectric` and `twosided`;
//! * emitters `point` and `constant` at the top level;
//! * one `perspective` sensor with an `hdrfilm` (explicit `box` filter) and an `independent`
//!   sampler, and an optional `path` integrator;
//! * every world-space coordinate within ±[`MAX_COORDINATE`] (1e18), where the renderer's f32
//!   arithmetic cannot overflow.

use std::cell::Cell;
use std::collections::HashMap;
use std::marker::PhantomData;
use std::path::Path;

use glam::{Mat3, Mat4, Vec3, Vec4};
use roxmltree::{Document, Node, NodeType};

use super::obj;
use super::scene::{
    BsdfDesc, CameraDesc, FovAxis, GeometryDesc, IntegratorDesc, MeshDesc, PointLightDesc, Rgb,
    SceneDesc, ShapeDesc,
};
use super::shapes::triangle_normal;
use crate::error::{Error, Num, Result};
use crate::limits::shorten;

/// Loads a Mitsuba 3 scene file; `obj` files it names are resolved relative to its folder.
///
/// Reading failures are [`Error::Io`]; everything the loader rejects is [`Error::Scene`].
pub fn load_file(path: &Path) -> Result<SceneDesc> {
    let xml = std::fs::read_to_string(path).map_err(|err| Error::io(path.display(), &err))?;
    let base_dir = path.parent().unwrap_or_else(|| Path::new(""));
    load_str(&xml, base_dir, &path.display().to_string())
}

/// Loads a Mitsuba 3 scene from its text; `obj` files are resolved relative to `base_dir` and
/// `source` is the file name used in error messages.
pub fn load_str(xml: &str, base_dir: &Path, source: &str) -> Result<SceneDesc> {
    load_counting(xml, base_dir, source).0
}

/// [`load_str`], also returning how many line numbers the load looked up (for a test: a
/// successful load looks up none).
fn load_counting(xml: &str, base_dir: &Path, source: &str) -> (Result<SceneDesc>, usize) {
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
const OBJECT_TAGS: &[&str] = &["bsdf", "emitter", "ref", "film", "sampler", "rfilter"];

/// Mitsuba's named indices of refraction (its `lookup_ior` table).
const NAMED_IORS: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.00004),
    ("hydrogen", 1.00013),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.5750),
    ("diamond", 2.419),
];

/// Mitsuba's `hdrfilm` pixel formats; accepted and ignored (they do not change pixel values).
const PIXEL_FORMATS: &[&str] = &["luminance", "luminance_alpha", "rgb", "rgba", "xyz", "xyza"];

/// Mitsuba's `hdrfilm` component formats; accepted and ignored.
const COMPONENT_FORMATS: &[&str] = &["float16", "float32", "uint32"];

/// Relative tolerance for "uniform scale" and "no scale" checks on transforms (f32 input).
const SIMILARITY_TOLERANCE: f32 = 1e-4;

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
type At<'a, 'i, T> = Option<(T, Node<'a, 'i>)>;

/// The value of an optional parameter, or its default.
fn value_or<T>(at: At<'_, '_, T>, default: T) -> T {
    at.map_or(default, |(value, _)| value)
}

/// How an element is named in messages: its tag and its `type` (or `name`, or `id`) attribute,
/// as written in the file.
fn describe(node: Node) -> String {
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
fn list(items: &[&str]) -> String {
    items.join(", ")
}

/// An f32 as messages print numbers ([`Num::from_f32`]).
fn num(x: f32) -> Num {
    Num::from_f32(x)
}

/// `(x, y, z)` with [`num`] components.
fn vec_text(v: Vec3) -> String {
    format!("({}, {}, {})", num(v.x), num(v.y), num(v.z))
}

/// A matrix row `x y z w` with [`num`] entries.
fn row_text(r: Vec4) -> String {
    format!("{} {} {} {}", num(r.x), num(r.y), num(r.z), num(r.w))
}

/// A 4x4 matrix, row by row, with [`num`] entries.
fn mat_text(m: Mat4) -> String {
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
fn edit_distance(a: &str, b: &str) -> usize {
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

/// One value element of a plugin, and whether the plugin asked for it.
struct Param<'a, 'i> {
    /// The `name` attribute (after `$` substitution).
    name: String,
    /// The element, for messages and for reading its value.
    node: Node<'a, 'i>,
    /// Set once the plugin has queried this name.
    used: bool,
}

/// The parameters and nested objects of one plugin element.
///
/// Like Mitsuba's `Properties` (which warns about unqueried properties) and pbrt-v4's
/// `ReportUnused`, it records every name the plugin asks for; whatever was given but never
/// asked for is reported by [`Props::finish`] as an error. This is what turns a misspelt
/// parameter (`reflectanse`) into an error instead of a silently used default, without each
/// plugin having to list its parameters twice. The recorded names double as the list of
/// supported parameters in the message.
struct Props<'a, 'i> {
    /// The plugin element.
    owner: Node<'a, 'i>,
    /// Its value elements, in document order.
    params: Vec<Param<'a, 'i>>,
    /// Position in `params` of each name: a hash map, so that a plugin with many parameters
    /// (a hostile file may give a million) is read in linear time.
    by_name: HashMap<String, usize>,
    /// Its nested objects in document order, each with a flag set once the plugin took it.
    objects: Vec<(Node<'a, 'i>, bool)>,
    /// Every parameter name the plugin queried, in query order.
    known: Vec<&'static str>,
}

impl<'a, 'i> Props<'a, 'i> {
    /// Sorts the children of `owner` into values and objects; rejects unknown tags, malformed
    /// value elements and a name given twice.
    fn collect(ld: &Loader<'a, 'i>, owner: Node<'a, 'i>) -> Result<Self> {
        let mut params: Vec<Param<'a, 'i>> = Vec::new();
        let mut by_name: HashMap<String, usize> = HashMap::new();
        let mut objects = Vec::new();
        for child in ld.elements(owner)? {
            let tag = child.tag_name().name();
            if VALUE_TAGS.contains(&tag) {
                let allowed: &[&str] = match tag {
                    "point" | "vector" => &["name", "value", "x", "y", "z"],
                    "transform" => &["name"],
                    _ => &["name", "value"],
                };
                ld.check_attrs(child, allowed)?;
                let name = ld.required_attr(child, "name")?;
                if tag != "transform" {
                    ld.leaf(child)?;
                }
                if let Some(&first) = by_name.get(&name) {
                    return Err(ld.err(
                        child,
                        format!(
                            "parameter \"{}\" given twice in <{}> (first at line {})",
                            shorten(&name),
                            describe(owner),
                            ld.line(params[first].node)
                        ),
                    ));
                }
                by_name.insert(name.clone(), params.len());
                params.push(Param {
                    name,
                    node: child,
                    used: false,
                });
            } else if OBJECT_TAGS.contains(&tag) {
                objects.push((child, false));
            } else {
                return Err(ld.err(
                    child,
                    format!(
                        "unsupported element <{}> inside <{}> (line {})",
                        shorten(tag),
                        describe(owner),
                        ld.line(owner)
                    ),
                ));
            }
        }
        Ok(Props {
            owner,
            params,
            by_name,
            objects,
            known: Vec::new(),
        })
    }

    /// Marks `name` as supported and returns its element, if given.
    fn take(&mut self, name: &'static str) -> Option<Node<'a, 'i>> {
        if !self.known.contains(&name) {
            self.known.push(name);
        }
        let param = &mut self.params[*self.by_name.get(name)?];
        param.used = true;
        Some(param.node)
    }

    /// Like [`Props::take`], and checks that the element is one of the value `kinds`.
    fn typed(
        &mut self,
        ld: &Loader<'a, 'i>,
        name: &'static str,
        kinds: &[&str],
    ) -> Result<Option<Node<'a, 'i>>> {
        let Some(node) = self.take(name) else {
            return Ok(None);
        };
        let tag = node.tag_name().name();
        if kinds.contains(&tag) {
            return Ok(Some(node));
        }
        let wanted: Vec<String> = kinds.iter().map(|k| format!("<{k}>")).collect();
        Err(ld.err(
            node,
            format!(
                "parameter \"{name}\" of <{}> must be given as {}, not <{tag}>",
                describe(self.owner),
                wanted.join(" or ")
            ),
        ))
    }

    /// A `<float>` parameter.
    fn float(&mut self, ld: &Loader<'a, 'i>, name: &'static str) -> Result<At<'a, 'i, f32>> {
        let Some(node) = self.typed(ld, name, &["float"])? else {
            return Ok(None);
        };
        let text = ld.required_attr(node, "value")?;
        Ok(Some((ld.number(node, "value", &text)?, node)))
    }

    /// An `<integer>` parameter.
    fn integer(&mut self, ld: &Loader<'a, 'i>, name: &'static str) -> Result<At<'a, 'i, i64>> {
        let Some(node) = self.typed(ld, name, &["integer"])? else {
            return Ok(None);
        };
        let text = ld.required_attr(node, "value")?;
        let trimmed = text.trim();
        let value = trimmed.parse::<i64>().map_err(|_| {
            let digits = trimmed.strip_prefix(['-', '+']).unwrap_or(trimmed);
            let why = if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
                "is out of the 64-bit integer range"
            } else {
                "is not an integer"
            };
            ld.err(node, format!("value=\"{}\" {why}", shorten(&text)))
        })?;
        Ok(Some((value, node)))
    }

    /// A `<boolean>` parameter (`true` or `false`, in any case, as Mitsuba reads it).
    fn boolean(&mut self, ld: &Loader<'a, 'i>, name: &'static str) -> Result<At<'a, 'i, bool>> {
        let Some(node) = self.typed(ld, name, &["boolean"])? else {
            return Ok(None);
        };
        let text = ld.required_attr(node, "value")?;
        let value = match text.trim().to_ascii_lowercase().as_str() {
            "true" => true,
            "false" => false,
            _ => {
                return Err(ld.err(
                    node,
                    format!(
                        "value=\"{}\" is not a boolean (true or false)",
                        shorten(&text)
                    ),
                ));
            }
        };
        Ok(Some((value, node)))
    }

    /// A `<string>` parameter.
    fn string(&mut self, ld: &Loader<'a, 'i>, name: &'static str) -> Result<At<'a, 'i, String>> {
        let Some(node) = self.typed(ld, name, &["string"])? else {
            return Ok(None);
        };
        Ok(Some((ld.required_attr(node, "value")?, node)))
    }

    /// A spectrum parameter: `<rgb>` (one number means grey) or `<float>` (grey); negative
    /// components are rejected.
    fn spectrum(&mut self, ld: &Loader<'a, 'i>, name: &'static str) -> Result<At<'a, 'i, Rgb>> {
        let Some(node) = self.typed(ld, name, &["rgb", "float"])? else {
            return Ok(None);
        };
        let text = ld.required_attr(node, "value")?;
        let value = if node.tag_name().name() == "float" {
            Rgb::splat(ld.number(node, "value", &text)?)
        } else {
            match ld.numbers(node, "value", &text)?.as_slice() {
                [grey] => Rgb::splat(*grey),
                [r, g, b] => Rgb::new(*r, *g, *b),
                other => {
                    return Err(ld.err(
                        node,
                        format!(
                            "value=\"{}\" must hold 1 or 3 numbers, found {}",
                            shorten(&text),
                            other.len()
                        ),
                    ));
                }
            }
        };
        if value.min_element() < 0.0 {
            return Err(ld.err(
                node,
                format!("value=\"{}\" has a negative component", shorten(&text)),
            ));
        }
        Ok(Some((value, node)))
    }

    /// A `<point>` parameter (`value="x, y, z"` or `x`/`y`/`z` attributes defaulting to 0).
    fn point(&mut self, ld: &Loader<'a, 'i>, name: &'static str) -> Result<At<'a, 'i, Vec3>> {
        let Some(node) = self.typed(ld, name, &["point"])? else {
            return Ok(None);
        };
        Ok(Some((ld.xyz(node, 0.0)?, node)))
    }

    /// A `<transform>` parameter.
    fn transform(&mut self, ld: &Loader<'a, 'i>, name: &'static str) -> Result<At<'a, 'i, Mat4>> {
        let Some(node) = self.typed(ld, name, &["transform"])? else {
            return Ok(None);
        };
        Ok(Some((ld.transform(node)?, node)))
    }

    /// An index of refraction: a `<float>` or a `<string>` naming a material in Mitsuba's table.
    fn ior(&mut self, ld: &Loader<'a, 'i>, name: &'static str) -> Result<At<'a, 'i, f32>> {
        let Some(node) = self.typed(ld, name, &["float", "string"])? else {
            return Ok(None);
        };
        let text = ld.required_attr(node, "value")?;
        let value = if node.tag_name().name() == "float" {
            ld.number(node, "value", &text)?
        } else {
            let key = text.trim().to_ascii_lowercase();
            let Some(&(_, ior)) = NAMED_IORS.iter().find(|(n, _)| *n == key) else {
                let names: Vec<&str> = NAMED_IORS.iter().map(|(n, _)| *n).collect();
                return Err(ld.err(
                    node,
                    format!(
                        "unknown index of refraction \"{}\"; known names: {}",
                        shorten(&text),
                        list(&names)
                    ),
                ));
            };
            ior
        };
        if !(value > 0.0) {
            return Err(ld.err(
                node,
                format!(
                    "value=\"{}\": an index of refraction must be > 0",
                    shorten(&text)
                ),
            ));
        }
        Ok(Some((value, node)))
    }

    /// Rejects a Mitsuba parameter of this plugin that the renderer does not model, saying why
    /// (more helpful than "unknown parameter" for names that are valid in Mitsuba).
    fn reject(&mut self, ld: &Loader<'a, 'i>, name: &str, why: &str) -> Result<()> {
        match self.by_name.get(name).map(|&i| &self.params[i]) {
            Some(param) => Err(ld.err(
                param.node,
                format!(
                    "parameter \"{name}\" of <{}> is not supported: {why}",
                    describe(self.owner)
                ),
            )),
            None => Ok(()),
        }
    }

    /// Takes the nested objects whose tag is one of `tags`, in document order.
    fn objects(&mut self, tags: &[&str]) -> Vec<Node<'a, 'i>> {
        self.objects
            .iter_mut()
            .filter(|(node, _)| tags.contains(&node.tag_name().name()))
            .map(|(node, used)| {
                *used = true;
                *node
            })
            .collect()
    }

    /// Fails on the first (in document order) value or object the plugin did not take.
    fn finish(&self, ld: &Loader<'a, 'i>) -> Result<()> {
        let param = self.params.iter().find(|p| !p.used);
        let object = self.objects.iter().find(|(_, used)| !used).map(|(n, _)| *n);
        // Built only on failure: a line lookup per plugin was what made loading quadratic.
        let owner = || format!("<{}> (line {})", describe(self.owner), ld.line(self.owner));
        match (param, object) {
            (Some(param), object)
                if object.is_none_or(|o| param.node.range().start < o.range().start) =>
            {
                let name = &param.name;
                let supported = if self.known.is_empty() {
                    "it takes no parameters".to_string()
                } else {
                    format!("supported parameters: {}", list(&self.known))
                };
                let hint = self
                    .known
                    .iter()
                    .filter(|k| edit_distance(k, name) <= 2)
                    .min_by_key(|k| edit_distance(k, name))
                    .map(|k| format!(" (did you mean \"{k}\"?)"))
                    .unwrap_or_default();
                Err(ld.err(
                    param.node,
                    format!(
                        "unknown parameter \"{}\"{hint} for {}; {supported}",
                        shorten(name),
                        owner()
                    ),
                ))
            }
            (_, Some(object)) => Err(ld.err(object, format!("not allowed inside {}", owner()))),
            _ => Ok(()),
        }
    }
}

/// A top-level emitter.
enum TopEmitter {
    /// `point`.
    Point(PointLightDesc),
    /// `constant`, with its radiance.
    Constant(Rgb),
}

/// Loader state: line starts, `$` defaults and the ids declared so far. Declarations keep the
/// byte offset of their element; its line is looked up only for a message.
struct Loader<'a, 'i> {
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
    bsdfs: HashMap<String, BsdfDesc>,
    /// Every declared id, with the element and offset that declared it.
    ids: HashMap<String, (String, usize)>,
}

impl<'a, 'i> Loader<'a, 'i> {
    /// 1-based line at which `node` starts.
    fn line(&self, node: Node) -> u32 {
        self.lines.line(node.range().start)
    }

    /// An [`Error::Scene`] about `node`.
    fn err(&self, node: Node, message: impl Into<String>) -> Error {
        Error::Scene {
            file: self.file.to_string(),
            line: self.line(node),
            element: describe(node),
            message: message.into(),
        }
    }

    /// The element children of `node`; comments are skipped and stray text is an error.
    fn elements(&self, node: Node<'a, 'i>) -> Result<Vec<Node<'a, 'i>>> {
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
    fn leaf(&self, node: Node<'a, 'i>) -> Result<()> {
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
    fn check_attrs(&self, node: Node, allowed: &[&str]) -> Result<()> {
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
    fn attr(&self, node: Node, name: &str) -> Result<Option<String>> {
        node.attribute(name)
            .map(|raw| self.substitute(node, name, raw))
            .transpose()
    }

    /// A required attribute after `$` substitution.
    fn required_attr(&self, node: Node, name: &str) -> Result<String> {
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
    fn number(&self, node: Node, attr: &str, text: &str) -> Result<f32> {
        match text.trim().parse::<f32>() {
            Ok(value) if value.is_finite() => Ok(value),
            _ => Err(self.err(
                node,
                format!("{attr}=\"{}\" is not a finite number", shorten(text)),
            )),
        }
    }

    /// Numbers separated by commas and/or whitespace.
    fn numbers(&self, node: Node, attr: &str, text: &str) -> Result<Vec<f32>> {
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
    fn xyz(&self, node: Node, default: f32) -> Result<Vec3> {
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
    fn transform(&self, node: Node<'a, 'i>) -> Result<Mat4> {
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
                "lookat" => {
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
    fn affine(&self, to_world: At<'a, 'i, Mat4>) -> Result<Mat4> {
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
        if parts.len() != 3 || parts.iter().any(|p| p.parse::<u32>().is_err()) || parts[0] != "3" {
            return Err(self.err(
                root,
                format!(
                    "version=\"{}\" is not a Mitsuba 3 version (3.x.y)",
                    shorten(version)
                ),
            ));
        }

        let mut integrator: At<'a, 'i, IntegratorDesc> = None;
        let mut sensor: At<'a, 'i, CameraDesc> = None;
        let mut environment: At<'a, 'i, Rgb> = None;
        let mut shapes = Vec::new();
        let mut point_lights = Vec::new();
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
                "emitter" => match self.emitter(child)? {
                    TopEmitter::Point(light) => point_lights.push(light),
                    TopEmitter::Constant(radiance) => {
                        if let Some((_, first)) = environment {
                            return Err(self.err(
                                child,
                                format!(
                                    "a second constant emitter: at most one is supported (the \
                                     first is at line {})",
                                    self.line(first)
                                ),
                            ));
                        }
                        environment = Some((radiance, child));
                    }
                },
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
            point_lights,
            environment: environment.map(|(radiance, _)| radiance),
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

    /// `<integrator type="path">`.
    fn integrator(&mut self, node: Node<'a, 'i>) -> Result<IntegratorDesc> {
        self.check_attrs(node, &["type", "id"])?;
        self.register_id(node)?;
        self.plugin_type(node, "integrator", &["path"])?;
        let mut props = Props::collect(self, node)?;
        let max_depth = props.integer(self, "max_depth")?;
        let rr_depth = props.integer(self, "rr_depth")?;
        props.finish(self)?;

        let max_depth = match max_depth {
            None | Some((-1, _)) => None,
            Some((0, at)) => {
                return Err(self.err(
                    at,
                    "max_depth = 0 would render nothing, not even emitters; use -1 (unbounded) \
                     or a depth >= 1",
                ));
            }
            Some((depth, at)) => Some(u32::try_from(depth).map_err(|_| {
                self.err(
                    at,
                    format!("max_depth = {depth}: must be -1 (unbounded) or in 1..=4294967295"),
                )
            })?),
        };
        let rr_depth = match rr_depth {
            None => IntegratorDesc::default().rr_depth,
            Some((depth, at)) => {
                u32::try_from(depth)
                    .ok()
                    .filter(|d| *d >= 1)
                    .ok_or_else(|| {
                        self.err(at, format!("rr_depth = {depth}: must be in 1..=4294967295"))
                    })?
            }
        };
        Ok(IntegratorDesc {
            max_depth,
            rr_depth,
        })
    }

    /// `<sensor type="perspective">` with its film and sampler.
    fn sensor(&mut self, node: Node<'a, 'i>) -> Result<CameraDesc> {
        self.check_attrs(node, &["type", "id"])?;
        self.register_id(node)?;
        self.plugin_type(node, "sensor", &["perspective"])?;
        let mut props = Props::collect(self, node)?;
        let films = props.objects(&["film"]);
        let samplers = props.objects(&["sampler"]);
        let fov = props.float(self, "fov")?;
        let fov_axis = props.string(self, "fov_axis")?;
        let to_world = props.transform(self, "to_world")?;
        let near_clip = props.float(self, "near_clip")?;
        let far_clip = props.float(self, "far_clip")?;
        props.reject(
            self,
            "focal_length",
            "give the field of view as <float name=\"fov\"> instead",
        )?;
        props.finish(self)?;

        let Some((fov_deg, fov_at)) = fov else {
            return Err(self.err(node, "missing required parameter <float name=\"fov\">"));
        };
        if !(fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(self.err(
                fov_at,
                format!("fov = {}: must be in (0, 180) degrees", num(fov_deg)),
            ));
        }
        let fov_axis = match fov_axis {
            None => FovAxis::X,
            Some((axis, at)) => match axis.as_str() {
                "x" => FovAxis::X,
                "y" => FovAxis::Y,
                "diagonal" => FovAxis::Diagonal,
                "smaller" => FovAxis::Smaller,
                "larger" => FovAxis::Larger,
                _ => {
                    return Err(self.err(
                        at,
                        format!(
                            "fov_axis = \"{}\": must be x, y, diagonal, smaller or larger",
                            shorten(&axis)
                        ),
                    ));
                }
            },
        };
        let to_world_at = to_world.map(|(_, at)| at);
        let to_world = self.affine(to_world)?;
        let origin = to_world.w_axis.truncate();
        if let Some(reach) = beyond_limit(origin) {
            let what = format!("the camera position {}", vec_text(origin));
            return Err(self.err(to_world_at.unwrap_or(node), beyond_message(&what, reach)));
        }
        if let Some(at) = to_world_at {
            let linear = Mat3::from_mat4(to_world);
            let lengths = Vec3::new(
                linear.x_axis.length(),
                linear.y_axis.length(),
                linear.z_axis.length(),
            );
            let dots = Vec3::new(
                linear.x_axis.dot(linear.y_axis),
                linear.y_axis.dot(linear.z_axis),
                linear.z_axis.dot(linear.x_axis),
            );
            if (lengths - Vec3::ONE).abs().max_element() > SIMILARITY_TOLERANCE
                || dots.abs().max_element() > SIMILARITY_TOLERANCE
            {
                return Err(self.err(
                    at,
                    format!(
                        "the camera transform scales or shears (axis lengths {}, \
                         pairwise dot products {}); Mitsuba forbids scale factors in a \
                         camera-to-world transform",
                        vec_text(lengths),
                        vec_text(dots)
                    ),
                ));
            }
        }
        let near = value_or(near_clip, 0.01);
        let far = value_or(far_clip, 10000.0);
        if !(near > 0.0) {
            let at = near_clip.map_or(node, |(_, at)| at);
            return Err(self.err(at, format!("near_clip = {}: must be > 0", num(near))));
        }
        if !(far > near) {
            let at = far_clip.or(near_clip).map_or(node, |(_, at)| at);
            return Err(self.err(
                at,
                format!(
                    "far_clip = {} must exceed near_clip = {}",
                    num(far),
                    num(near)
                ),
            ));
        }

        let (width, height) = match films.as_slice() {
            [] => {
                return Err(self.err(
                    node,
                    "missing <film type=\"hdrfilm\">: Mitsuba's default film reconstructs with \
                     a gaussian filter, which is not modelled; add an hdrfilm with \
                     <rfilter type=\"box\"/>",
                ));
            }
            [film] => self.film(*film)?,
            [_, second, ..] => {
                return Err(self.err(*second, "a sensor takes exactly one <film>"));
            }
        };
        let spp = match samplers.as_slice() {
            // Mitsuba's default sampler is `independent` with 4 samples per pixel.
            [] => 4,
            [sampler] => self.sampler(*sampler)?,
            [_, second, ..] => {
                return Err(self.err(*second, "a sensor takes at most one <sampler>"));
            }
        };
        Ok(CameraDesc {
            to_world,
            fov_deg,
            fov_axis,
            width,
            height,
            spp,
            near_clip: near,
            far_clip: far,
        })
    }

    /// `<film type="hdrfilm">` with an explicit box `rfilter`; returns (width, height).
    fn film(&self, node: Node<'a, 'i>) -> Result<(u32, u32)> {
        self.check_attrs(node, &["type", "name"])?;
        self.plugin_type(node, "film", &["hdrfilm"])?;
        let mut props = Props::collect(self, node)?;
        let filters = props.objects(&["rfilter"]);
        let width = props.integer(self, "width")?;
        let height = props.integer(self, "height")?;
        let pixel_format = props.string(self, "pixel_format")?;
        let component_format = props.string(self, "component_format")?;
        props.finish(self)?;

        let mut size = [768, 576];
        for (slot, given, name) in [(0, width, "width"), (1, height, "height")] {
            if let Some((value, at)) = given {
                size[slot] = u32::try_from(value)
                    .ok()
                    .filter(|v| *v >= 1)
                    .ok_or_else(|| {
                        self.err(at, format!("{name} = {value}: must be in 1..=4294967295"))
                    })?;
            }
        }
        for (given, allowed) in [
            (pixel_format, PIXEL_FORMATS),
            (component_format, COMPONENT_FORMATS),
        ] {
            if let Some((value, at)) = given {
                if !allowed.contains(&value.as_str()) {
                    return Err(self.err(
                        at,
                        format!("\"{}\" is not one of {}", shorten(&value), list(allowed)),
                    ));
                }
            }
        }
        match filters.as_slice() {
            [] => Err(self.err(
                node,
                "missing <rfilter type=\"box\"/>: Mitsuba's default reconstruction filter is \
                 gaussian, which is not modelled; give the box filter explicitly",
            )),
            [filter] => {
                self.check_attrs(*filter, &["type", "name"])?;
                self.plugin_type(*filter, "rfilter", &["box"])?;
                Props::collect(self, *filter)?.finish(self)?;
                Ok((size[0], size[1]))
            }
            [_, second, ..] => Err(self.err(*second, "a film takes exactly one <rfilter>")),
        }
    }

    /// `<sampler type="independent">`; returns its `sample_count`.
    fn sampler(&self, node: Node<'a, 'i>) -> Result<u32> {
        self.check_attrs(node, &["type", "name"])?;
        self.plugin_type(node, "sampler", &["independent"])?;
        let mut props = Props::collect(self, node)?;
        let count = props.integer(self, "sample_count")?;
        // The seed only selects Mitsuba's random sequence; accepted and not used.
        props.integer(self, "seed")?;
        props.finish(self)?;
        match count {
            None => Ok(4),
            Some((value, at)) => u32::try_from(value)
                .ok()
                .filter(|v| *v >= 1)
                .ok_or_else(|| {
                    self.err(
                        at,
                        format!("sample_count = {value}: must be in 1..=4294967295"),
                    )
                }),
        }
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

    /// A BSDF nested in a shape or `twosided`: a `<bsdf>` or a `<ref>` to a top-level one.
    fn nested_bsdf(&self, node: Node<'a, 'i>) -> Result<BsdfDesc> {
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
    fn bsdf(&self, node: Node<'a, 'i>) -> Result<BsdfDesc> {
        let ty = self.plugin_type(
            node,
            "bsdf",
            &[
                "diffuse",
                "conductor",
                "roughconductor",
                "dielectric",
                "twosided",
            ],
        )?;
        let mut props = Props::collect(self, node)?;
        let one = Rgb::ONE;
        let bsdf = match ty.as_str() {
            "diffuse" => {
                let reflectance = props.spectrum(self, "reflectance")?;
                props.finish(self)?;
                BsdfDesc::Diffuse {
                    reflectance: value_or(reflectance, Rgb::splat(0.5)),
                }
            }
            "conductor" => {
                self.reject_complex_ior(&mut props)?;
                let material = props.string(self, "material")?;
                let tint = props.spectrum(self, "specular_reflectance")?;
                props.finish(self)?;
                self.check_material(material)?;
                BsdfDesc::Conductor {
                    specular_reflectance: value_or(tint, one),
                }
            }
            "roughconductor" => {
                self.reject_complex_ior(&mut props)?;
                for name in ["alpha_u", "alpha_v"] {
                    props.reject(
                        self,
                        name,
                        "anisotropic roughness is not modelled; use <float name=\"alpha\">",
                    )?;
                }
                let distribution = props.string(self, "distribution")?;
                let alpha = props.float(self, "alpha")?;
                let material = props.string(self, "material")?;
                let sample_visible = props.boolean(self, "sample_visible")?;
                let tint = props.spectrum(self, "specular_reflectance")?;
                props.finish(self)?;
                match distribution {
                    None => {
                        return Err(self.err(
                            node,
                            "missing <string name=\"distribution\" value=\"ggx\"/>: Mitsuba's \
                             default distribution is beckmann, which is not modelled; give ggx \
                             explicitly",
                        ));
                    }
                    Some((d, at)) if d != "ggx" => {
                        return Err(self.err(
                            at,
                            format!(
                                "distribution \"{}\" is not modelled; only \"ggx\" is",
                                shorten(&d)
                            ),
                        ));
                    }
                    Some(_) => {}
                }
                if let Some((false, at)) = sample_visible {
                    return Err(self.err(
                        at,
                        "sample_visible = false is not modelled; only true (Mitsuba's default)",
                    ));
                }
                self.check_material(material)?;
                let alpha_value = value_or(alpha, 0.1);
                if !(alpha_value > 0.0) {
                    let at = alpha.map_or(node, |(_, at)| at);
                    return Err(self.err(
                        at,
                        format!(
                            "alpha = {}: must be > 0 (use a conductor for a perfect mirror)",
                            num(alpha_value)
                        ),
                    ));
                }
                BsdfDesc::RoughConductor {
                    alpha: alpha_value,
                    specular_reflectance: value_or(tint, one),
                }
            }
            "dielectric" => {
                let int_ior = props.ior(self, "int_ior")?;
                let ext_ior = props.ior(self, "ext_ior")?;
                let reflect = props.spectrum(self, "specular_reflectance")?;
                let transmit = props.spectrum(self, "specular_transmittance")?;
                props.finish(self)?;
                BsdfDesc::Dielectric {
                    int_ior: value_or(int_ior, 1.5046),
                    ext_ior: value_or(ext_ior, 1.000277),
                    specular_reflectance: value_or(reflect, one),
                    specular_transmittance: value_or(transmit, one),
                }
            }
            "twosided" => {
                let inner = props.objects(&["bsdf", "ref"]);
                props.finish(self)?;
                let inner = match inner.as_slice() {
                    [] => return Err(self.err(node, "twosided needs one nested <bsdf>")),
                    [inner] => *inner,
                    [_, second, ..] => {
                        return Err(self.err(
                            *second,
                            "a second bsdf in twosided: different front and back BSDFs are not \
                             supported",
                        ));
                    }
                };
                // Checked before reading the inner bsdf: reading it first let a file of twosided
                // nested a million deep recurse until the stack overflowed.
                let inner_type = match inner.tag_name().name() {
                    "bsdf" => self.attr(inner, "type")?,
                    _ => None,
                };
                if matches!(inner_type.as_deref(), Some("twosided" | "dielectric")) {
                    return Err(
                        self.err(inner, "twosided cannot wrap a twosided or dielectric bsdf")
                    );
                }
                let nested = self.nested_bsdf(inner)?;
                match nested {
                    BsdfDesc::TwoSided(_) | BsdfDesc::Dielectric { .. } => {
                        return Err(
                            self.err(inner, "twosided cannot wrap a twosided or dielectric bsdf")
                        );
                    }
                    _ => BsdfDesc::TwoSided(Box::new(nested)),
                }
            }
            _ => unreachable!("plugin_type accepted {ty}"),
        };
        Ok(bsdf)
    }

    /// Conductors model only Mitsuba's `material="none"`: complex indices are rejected.
    fn reject_complex_ior(&self, props: &mut Props<'a, 'i>) -> Result<()> {
        for name in ["eta", "k"] {
            props.reject(
                self,
                name,
                "complex indices of refraction are not modelled; only material=\"none\" (a \
                 mirror tinted by specular_reflectance)",
            )?;
        }
        Ok(())
    }

    /// A conductor's `material`, which may only be `none` (also Mitsuba 3's default).
    fn check_material(&self, material: At<'a, 'i, String>) -> Result<()> {
        match material {
            Some((name, at)) if name != "none" => Err(self.err(
                at,
                format!(
                    "material \"{}\" is not modelled; only \"none\" (a mirror tinted by \
                     specular_reflectance)",
                    shorten(&name)
                ),
            )),
            _ => Ok(()),
        }
    }

    /// A top-level `<emitter>`: `point` or `constant`.
    fn emitter(&mut self, node: Node<'a, 'i>) -> Result<TopEmitter> {
        self.check_attrs(node, &["type", "id"])?;
        if node.attribute("type") == Some("area") {
            return Err(self.err(node, "an area emitter must be nested inside a <shape>"));
        }
        let ty = self.plugin_type(node, "emitter", &["point", "constant"])?;
        self.register_id(node)?;
        let mut props = Props::collect(self, node)?;
        if ty == "constant" {
            let radiance = props.spectrum(self, "radiance")?;
            props.finish(self)?;
            let (radiance, _) = radiance.ok_or_else(|| {
                self.err(node, "missing required parameter <rgb name=\"radiance\">")
            })?;
            return Ok(TopEmitter::Constant(radiance));
        }
        let intensity = props.spectrum(self, "intensity")?;
        let position = props.point(self, "position")?;
        let to_world = props.transform(self, "to_world")?;
        props.finish(self)?;
        let (intensity, _) = intensity
            .ok_or_else(|| self.err(node, "missing required parameter <rgb name=\"intensity\">"))?;
        let position = match (position, to_world) {
            (Some(_), Some((_, at))) => {
                return Err(self.err(
                    at,
                    "give either position or to_world for a point emitter, not both",
                ));
            }
            (Some((p, _)), None) => p,
            (None, to_world) => self.affine(to_world)?.w_axis.truncate(),
        };
        if let Some(reach) = beyond_limit(position) {
            let what = format!("the point light at {}", vec_text(position));
            return Err(self.err(node, beyond_message(&what, reach)));
        }
        Ok(TopEmitter::Point(PointLightDesc {
            position,
            intensity,
        }))
    }

    /// A `<shape>` with its BSDF and optional area emitter.
    fn shape(&mut self, node: Node<'a, 'i>) -> Result<ShapeDesc> {
        self.check_attrs(node, &["type", "id"])?;
        let ty = self.plugin_type(
            node,
            "shape",
            &["rectangle", "cube", "sphere", "disk", "obj"],
        )?;
        self.register_id(node)?;
        let mut props = Props::collect(self, node)?;
        let bsdfs = props.objects(&["bsdf", "ref"]);
        let emitters = props.objects(&["emitter"]);
        props.reject(
            self,
            "flip_normals",
            "Mitsuba's flip_normals is not modelled; orient the shape with to_world",
        )?;
        let geometry = match ty.as_str() {
            "rectangle" | "cube" => {
                let to_world = props.transform(self, "to_world")?;
                props.finish(self)?;
                let to_world = self.affine(to_world)?;
                let (positions, indices) = if ty == "rectangle" {
                    rectangle_mesh()
                } else {
                    cube_mesh()
                };
                GeometryDesc::Mesh(transform_mesh(positions, None, indices, to_world))
            }
            "sphere" => {
                let center = props.point(self, "center")?;
                let radius = props.float(self, "radius")?;
                let to_world = props.transform(self, "to_world")?;
                props.finish(self)?;
                self.sphere(node, center, radius, to_world)?
            }
            "disk" => {
                let to_world = props.transform(self, "to_world")?;
                props.finish(self)?;
                GeometryDesc::Disk {
                    to_world: self.affine(to_world)?,
                }
            }
            "obj" => {
                let filename = props.string(self, "filename")?;
                let face_normals = props.boolean(self, "face_normals")?;
                let to_world = props.transform(self, "to_world")?;
                props.finish(self)?;
                let Some((filename, at)) = filename else {
                    return Err(self.err(
                        node,
                        "missing required parameter <string name=\"filename\">",
                    ));
                };
                let to_world = self.affine(to_world)?;
                GeometryDesc::Mesh(self.obj(
                    at,
                    node,
                    &filename,
                    value_or(face_normals, false),
                    to_world,
                )?)
            }
            _ => unreachable!("plugin_type accepted {ty}"),
        };
        self.check_reach(node, &geometry)?;

        let bsdf = match bsdfs.as_slice() {
            [] => BsdfDesc::default(),
            [bsdf] => self.nested_bsdf(*bsdf)?,
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

    /// `sphere`: Mitsuba maps the unit sphere by `to_world · translate(center) · scale(radius)`,
    /// which must be a similarity (uniform scale, rotation, translation) without mirroring.
    fn sphere(
        &self,
        node: Node<'a, 'i>,
        center: At<'a, 'i, Vec3>,
        radius: At<'a, 'i, f32>,
        to_world: At<'a, 'i, Mat4>,
    ) -> Result<GeometryDesc> {
        let r = value_or(radius, 1.0);
        if !(r > 0.0) {
            let at = radius.map_or(node, |(_, at)| at);
            return Err(self.err(
                at,
                format!(
                    "radius = {}: must be > 0 (negative radii flip normals in Mitsuba, which \
                     is not modelled)",
                    num(r)
                ),
            ));
        }
        let at = to_world.map_or(node, |(_, at)| at);
        let to_world = self.affine(to_world)?;
        let full = to_world
            * Mat4::from_translation(value_or(center, Vec3::ZERO))
            * Mat4::from_scale(Vec3::splat(r));
        let linear = Mat3::from_mat4(full);
        let axes = [linear.x_axis, linear.y_axis, linear.z_axis];
        let lengths = Vec3::from_array(axes.map(Vec3::length));
        let world_radius = lengths.element_sum() / 3.0;
        let spread = lengths.max_element() - lengths.min_element();
        let skew = [
            axes[0].dot(axes[1]),
            axes[1].dot(axes[2]),
            axes[2].dot(axes[0]),
        ]
        .map(f32::abs)
        .into_iter()
        .fold(0.0, f32::max);
        if spread > SIMILARITY_TOLERANCE * world_radius
            || skew > SIMILARITY_TOLERANCE * world_radius * world_radius
        {
            return Err(self.err(
                at,
                format!(
                    "a sphere's to_world must be a uniform scale, rotation and translation; \
                     this one scales the axes by {} (non-uniform scale or shear)",
                    vec_text(lengths)
                ),
            ));
        }
        if linear.determinant() < 0.0 {
            return Err(self.err(
                at,
                "a sphere's to_world mirrors (negative determinant), which flips its normals \
                 in Mitsuba; not modelled",
            ));
        }
        // radius × scale can underflow to 0 (radius 1e-45) or overflow: the renderer drops such
        // a sphere, so say so here instead.
        if !(world_radius > 0.0 && world_radius.is_finite()) {
            let at = radius.map_or(at, |(_, at)| at);
            return Err(self.err(
                at,
                format!(
                    "the sphere's world-space radius (radius {} times the to_world scale) is \
                     {}, not a positive finite f32",
                    num(r),
                    num(world_radius)
                ),
            ));
        }
        Ok(GeometryDesc::Sphere {
            center: full.w_axis.truncate(),
            radius: world_radius,
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
        let mut props = Props::collect(self, node)?;
        let radiance = props.spectrum(self, "radiance")?;
        props.finish(self)?;
        radiance
            .map(|(radiance, _)| radiance)
            .ok_or_else(|| self.err(node, "missing required parameter <rgb name=\"radiance\">"))
    }

    /// Loads an OBJ file (relative to the scene's folder) as one world-space mesh.
    ///
    /// The file is read by [`obj::parse`] (Mitsuba's semantics: one mesh per file, vertices
    /// split per `v/vt/vn` triple, fan triangulation). Vertex normals from the file are kept
    /// unless `face_normals`; without them Mitsuba computes angle-weighted vertex normals, and
    /// so does this loader. `at` is the `filename` element and `shape` the shape, named in
    /// errors; errors inside the file name the OBJ file and its line.
    fn obj(
        &self,
        at: Node<'a, 'i>,
        shape: Node<'a, 'i>,
        filename: &str,
        face_normals: bool,
        to_world: Mat4,
    ) -> Result<MeshDesc> {
        let path = self.base_dir.join(filename);
        let bytes = std::fs::read(&path).map_err(|err| {
            self.err(
                at,
                format!("cannot read OBJ file {}: {err}", path.display()),
            )
        })?;
        // Materials (mtllib, usemtl) are ignored: the shape's BSDF comes from the scene file.
        let parsed = obj::parse(&bytes).map_err(|err| {
            self.err(
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
            return Err(self.err(
                at,
                format!("OBJ file {} contains no triangles", path.display()),
            ));
        }
        let file_normals = if face_normals { None } else { parsed.normals };
        let mut mesh = transform_mesh(parsed.positions, file_normals, parsed.indices, to_world);
        if let Some((i, reach)) = first_beyond_limit(&mesh.positions) {
            let what = format!(
                "OBJ file {}, line {}: vertex {}",
                path.display(),
                parsed.lines[i],
                vec_text(mesh.positions[i])
            );
            return Err(self.err(shape, beyond_message(&what, reach)));
        }
        if !face_normals && mesh.normals.is_none() {
            mesh.normals = Some(angle_weighted_normals(&mesh.positions, &mesh.indices));
        }
        Ok(mesh)
    }
}

/// The message for `what` reaching `reach`, beyond [`MAX_COORDINATE`].
fn beyond_message(what: &str, reach: f32) -> String {
    format!(
        "{what} reaches {} after to_world, beyond the renderer's coordinate limit of ±{} (its \
         f32 arithmetic would overflow and the shape would silently vanish)",
        num(reach),
        num(MAX_COORDINATE)
    )
}

/// The largest coordinate magnitude of `p`, if `p` is not finite or exceeds
/// [`MAX_COORDINATE`].
fn beyond_limit(p: Vec3) -> Option<f32> {
    let reach = p.abs().max_element();
    (!(p.is_finite() && reach <= MAX_COORDINATE)).then_some(reach)
}

/// The first point beyond [`MAX_COORDINATE`], with its largest coordinate magnitude.
fn first_beyond_limit(points: &[Vec3]) -> Option<(usize, f32)> {
    points
        .iter()
        .enumerate()
        .find_map(|(i, &p)| beyond_limit(p).map(|reach| (i, reach)))
}

/// Mitsuba's rectangle: the square `[-1,1]²` at `z = 0`, counter-clockwise seen from `+z`.
fn rectangle_mesh() -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let positions = vec![
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    ];
    (positions, vec![[0, 1, 2], [0, 2, 3]])
}

/// Mitsuba's cube: `[-1,1]³` as 6 faces of 2 triangles, each counter-clockwise seen from
/// outside (4 vertices per face, as in Mitsuba's mesh).
fn cube_mesh() -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut positions = Vec::with_capacity(24);
    let mut indices = Vec::with_capacity(12);
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let normal = Vec3::AXES[axis] * sign;
            // (u, v, normal) is right-handed, so corners in (u, v) order wind around `normal`.
            let (mut u, mut v) = (Vec3::AXES[(axis + 1) % 3], Vec3::AXES[(axis + 2) % 3]);
            if sign < 0.0 {
                std::mem::swap(&mut u, &mut v);
            }
            let first = positions.len() as u32;
            positions.extend([
                normal - u - v,
                normal + u - v,
                normal + u + v,
                normal - u + v,
            ]);
            indices.push([first, first + 1, first + 2]);
            indices.push([first, first + 2, first + 3]);
        }
    }
    (positions, indices)
}

/// Maps an object-space mesh to world space. Normals transform with the inverse transpose;
/// since `(M a) × (M b) = det(M) · M⁻ᵀ (a × b)`, a mirroring map (`det < 0`) would turn each
/// triangle's winding against its transformed normal, so the winding is reversed then to keep
/// triangles counter-clockwise seen from the front.
fn transform_mesh(
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    indices: Vec<[u32; 3]>,
    to_world: Mat4,
) -> MeshDesc {
    let linear = Mat3::from_mat4(to_world);
    let normal_matrix = linear.inverse().transpose();
    let mirrored = linear.determinant() < 0.0;
    MeshDesc {
        positions: positions
            .into_iter()
            .map(|p| to_world.transform_point3(p))
            .collect(),
        normals: normals.map(|ns| {
            ns.into_iter()
                .map(|n| (normal_matrix * n).normalize())
                .collect()
        }),
        indices: indices
            .into_iter()
            .map(|[a, b, c]| if mirrored { [a, c, b] } else { [a, b, c] })
            .collect(),
    }
}

/// The angle between two edges. glam's `angle_between` divides by `sqrt(|a|²·|b|²)`, which
/// overflows for edges beyond about 1e9 (a 1e10 ground plane got right angles everywhere), so
/// such edges are normalised first.
fn corner_angle(a: Vec3, b: Vec3) -> f32 {
    if (a.length_squared() * b.length_squared()).is_finite() {
        a.angle_between(b)
    } else {
        a.normalize_or_zero().angle_between(b.normalize_or_zero())
    }
}

/// Mitsuba's vertex normals for meshes without them: each triangle adds its unit normal weighted
/// by its angle at the vertex (Thürmer and Wüthrich 1998). Vertices touched only by degenerate
/// triangles get `+z` (those triangles have no area and are never hit).
fn angle_weighted_normals(positions: &[Vec3], indices: &[[u32; 3]]) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for tri in indices {
        let p = tri.map(|i| positions[i as usize]);
        // The plain cross product first (bit-identical normals for ordinary triangles), the
        // scale-safe one for triangles whose cross product overflows or underflows.
        let Some(normal) = (p[1] - p[0])
            .cross(p[2] - p[0])
            .try_normalize()
            .or_else(|| triangle_normal(&p))
        else {
            continue;
        };
        for k in 0..3 {
            let angle = corner_angle(p[(k + 1) % 3] - p[k], p[(k + 2) % 3] - p[k]);
            sums[tri[k] as usize] += normal * angle;
        }
    }
    sums.into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Z))
        .collect()
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
        let (scene, lookups) = load_counting(&xml, Path::new("."), "many.xml");
        assert_eq!(scene.expect("loads").shapes.len(), 2000);
        assert_eq!(lookups, 0);

        let bad = xml.replacen("</scene>", "<shape type=\"sphere\" id=\"s7\"/></scene>", 1);
        let (scene, lookups) = load_counting(&bad, Path::new("."), "many.xml");
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
        let source = include_str!("mitsuba.rs");
        let code = &source[..source.find("#[cfg(test)]").expect("this module")];
        assert!(!code.contains(concat!("text_pos", "_at(")));
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
