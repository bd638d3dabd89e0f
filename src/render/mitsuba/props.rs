//! Reading a plugin's parameters: each value element once, of the right kind, with every
//! unknown or unused one an error naming the element. Plugins read theirs through [`Params`].

use std::collections::HashMap;
use std::sync::Arc;

use glam::{Mat4, Vec3};
use roxmltree::Node;

use super::{At, Loader, OBJECT_TAGS, VALUE_TAGS, describe, edit_distance, list};
use crate::error::{Error, Result};
use crate::limits::shorten;
use crate::render::bsdfs::Bsdf;
use crate::render::bsdfs::ior::{dielectric_ior, dielectric_names};
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;

/// Mitsuba's `hdrfilm` pixel formats; accepted and ignored (they do not change pixel values).
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
/// asked for is reported by [`Params::finish`] as an error. This is what turns a misspelt
/// parameter (`reflectanse`) into an error instead of a silently used default, without each
/// plugin having to list its parameters twice. The recorded names double as the list of
/// supported parameters in the message.
pub struct Params<'l, 'a, 'i> {
    /// The loader, for values, errors and nested objects.
    ld: &'l Loader<'a, 'i>,
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

impl<'l, 'a, 'i> Params<'l, 'a, 'i> {
    /// Sorts the children of `owner` into values and objects; rejects unknown tags, malformed
    /// value elements and a name given twice.
    pub fn collect(ld: &'l Loader<'a, 'i>, owner: Node<'a, 'i>) -> Result<Self> {
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
                let name = ld.param_name(&ld.required_attr(child, "name")?);
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
        Ok(Params {
            ld,
            owner,
            params,
            by_name,
            objects,
            known: Vec::new(),
        })
    }

    /// The loader, for nested objects.
    pub fn loader(&self) -> &'l Loader<'a, 'i> {
        self.ld
    }

    /// The plugin element.
    pub fn owner(&self) -> Node<'a, 'i> {
        self.owner
    }

    /// An [`Error::Scene`] about `node`, or about the plugin element when `None`.
    pub fn err(&self, node: Option<Node<'a, 'i>>, message: impl Into<String>) -> Error {
        self.ld.err(node.unwrap_or(self.owner), message)
    }

    /// A `<float>` parameter, or `default`.
    pub fn float_or(&mut self, name: &'static str, default: f32) -> Result<f32> {
        Ok(self.float(name)?.map_or(default, |(v, _)| v))
    }

    /// A parameter Mitsuba lets be a texture: an `<rgb>` or `<float>` value, or a nested
    /// `<texture name="...">` (not both).
    pub fn texture(&mut self, name: &'static str) -> Result<At<'a, 'i, Spectrum>> {
        let constant = self.spectrum(name)?;
        let ld = self.ld;
        let mut nested = None;
        for (node, used) in self.objects.iter_mut() {
            if node.tag_name().name() != "texture" {
                continue;
            }
            let given = ld.attr(*node, "name")?.map(|n| ld.param_name(&n));
            if given.as_deref() == Some(name) {
                if let Some((first, _)) = nested {
                    return Err(ld.err(
                        *node,
                        format!(
                            "texture \"{name}\" given twice (first at line {})",
                            ld.line(first)
                        ),
                    ));
                }
                *used = true;
                nested = Some((*node, ()));
            }
        }
        match (constant, nested) {
            (Some((_, at)), Some((node, _))) => Err(ld.err(
                node,
                format!(
                    "parameter \"{name}\" given both as a value (line {}) and as a texture",
                    ld.line(at)
                ),
            )),
            (Some((c, at)), None) => Ok(Some((Spectrum::Constant(c), at))),
            (None, Some((node, _))) => Ok(Some((Spectrum::Texture(ld.texture(node)?), node))),
            (None, None) => Ok(None),
        }
    }

    /// The nested BSDFs (`<bsdf>` or `<ref>` to a declared one), loaded, in document order.
    pub fn nested_bsdfs(&mut self) -> Result<Vec<(Arc<dyn Bsdf>, Node<'a, 'i>)>> {
        let ld = self.ld;
        self.objects(&["bsdf", "ref"])
            .into_iter()
            .map(|node| Ok((ld.nested_bsdf(node)?, node)))
            .collect()
    }

    /// Marks every value and object as used (a plugin that is replaced wholesale, such as a
    /// reconstruction filter under the box override).
    pub fn ignore_all(&mut self) {
        self.params.iter_mut().for_each(|p| p.used = true);
        self.objects.iter_mut().for_each(|(_, used)| *used = true);
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

    /// Like [`Params::take`], and checks that the element is one of the value `kinds`.
    pub fn typed(&mut self, name: &'static str, kinds: &[&str]) -> Result<Option<Node<'a, 'i>>> {
        let Some(node) = self.take(name) else {
            return Ok(None);
        };
        let tag = node.tag_name().name();
        if kinds.contains(&tag) {
            return Ok(Some(node));
        }
        let wanted: Vec<String> = kinds.iter().map(|k| format!("<{k}>")).collect();
        Err(self.ld.err(
            node,
            format!(
                "parameter \"{name}\" of <{}> must be given as {}, not <{tag}>",
                describe(self.owner),
                wanted.join(" or ")
            ),
        ))
    }

    /// A `<float>` parameter.
    pub fn float(&mut self, name: &'static str) -> Result<At<'a, 'i, f32>> {
        let Some(node) = self.typed(name, &["float"])? else {
            return Ok(None);
        };
        let text = self.ld.required_attr(node, "value")?;
        Ok(Some((self.ld.number(node, "value", &text)?, node)))
    }

    /// An `<integer>` parameter.
    pub fn integer(&mut self, name: &'static str) -> Result<At<'a, 'i, i64>> {
        let Some(node) = self.typed(name, &["integer"])? else {
            return Ok(None);
        };
        let text = self.ld.required_attr(node, "value")?;
        let trimmed = text.trim();
        let value = trimmed.parse::<i64>().map_err(|_| {
            let digits = trimmed.strip_prefix(['-', '+']).unwrap_or(trimmed);
            let why = if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
                "is out of the 64-bit integer range"
            } else {
                "is not an integer"
            };
            self.ld
                .err(node, format!("value=\"{}\" {why}", shorten(&text)))
        })?;
        Ok(Some((value, node)))
    }

    /// A `<boolean>` parameter (`true` or `false`, in any case, as Mitsuba reads it).
    pub fn boolean(&mut self, name: &'static str) -> Result<At<'a, 'i, bool>> {
        let Some(node) = self.typed(name, &["boolean"])? else {
            return Ok(None);
        };
        let text = self.ld.required_attr(node, "value")?;
        let value = match text.trim().to_ascii_lowercase().as_str() {
            "true" => true,
            "false" => false,
            _ => {
                return Err(self.ld.err(
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
    pub fn string(&mut self, name: &'static str) -> Result<At<'a, 'i, String>> {
        let Some(node) = self.typed(name, &["string"])? else {
            return Ok(None);
        };
        Ok(Some((self.ld.required_attr(node, "value")?, node)))
    }

    /// A spectrum parameter: `<rgb>` (one number means grey) or `<float>` (grey); negative
    /// components are rejected.
    pub fn spectrum(&mut self, name: &'static str) -> Result<At<'a, 'i, Rgb>> {
        let Some(node) = self.typed(name, &["rgb", "float"])? else {
            return Ok(None);
        };
        let text = self.ld.required_attr(node, "value")?;
        let value = if node.tag_name().name() == "float" {
            Rgb::splat(self.ld.number(node, "value", &text)?)
        } else {
            match self.ld.numbers(node, "value", &text)?.as_slice() {
                [grey] => Rgb::splat(*grey),
                [r, g, b] => Rgb::new(*r, *g, *b),
                other => {
                    return Err(self.ld.err(
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
            return Err(self.ld.err(
                node,
                format!("value=\"{}\" has a negative component", shorten(&text)),
            ));
        }
        Ok(Some((value, node)))
    }

    /// A `<point>` parameter (`value="x, y, z"` or `x`/`y`/`z` attributes defaulting to 0).
    pub fn point(&mut self, name: &'static str) -> Result<At<'a, 'i, Vec3>> {
        let Some(node) = self.typed(name, &["point"])? else {
            return Ok(None);
        };
        Ok(Some((self.ld.xyz(node, 0.0)?, node)))
    }

    /// A `<transform>` parameter.
    pub fn transform(&mut self, name: &'static str) -> Result<At<'a, 'i, Mat4>> {
        let Some(node) = self.typed(name, &["transform"])? else {
            return Ok(None);
        };
        Ok(Some((self.ld.transform(node)?, node)))
    }

    /// An index of refraction: a `<float>` or a `<string>` naming a material in Mitsuba's table.
    pub fn ior(&mut self, name: &'static str) -> Result<At<'a, 'i, f32>> {
        let Some(node) = self.typed(name, &["float", "string"])? else {
            return Ok(None);
        };
        let text = self.ld.required_attr(node, "value")?;
        let value = if node.tag_name().name() == "float" {
            self.ld.number(node, "value", &text)?
        } else {
            let Some(ior) = dielectric_ior(text.trim()) else {
                return Err(self.ld.err(
                    node,
                    format!(
                        "unknown index of refraction \"{}\"; known names: {}",
                        shorten(&text),
                        dielectric_names()
                    ),
                ));
            };
            ior
        };
        if !(value > 0.0) {
            return Err(self.ld.err(
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
    pub fn reject(&mut self, name: &str, why: &str) -> Result<()> {
        match self.by_name.get(name).map(|&i| &self.params[i]) {
            Some(param) => Err(self.ld.err(
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
    pub fn objects(&mut self, tags: &[&str]) -> Vec<Node<'a, 'i>> {
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
    pub fn finish(&self) -> Result<()> {
        let param = self.params.iter().find(|p| !p.used);
        let object = self.objects.iter().find(|(_, used)| !used).map(|(n, _)| *n);
        // Built only on failure: a line lookup per plugin was what made loading quadratic.
        let owner = || {
            format!(
                "<{}> (line {})",
                describe(self.owner),
                self.ld.line(self.owner)
            )
        };
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
                Err(self.ld.err(
                    param.node,
                    format!(
                        "unknown parameter \"{}\"{hint} for {}; {supported}",
                        shorten(name),
                        owner()
                    ),
                ))
            }
            (_, Some(object)) => Err(self
                .ld
                .err(object, format!("not allowed inside {}", owner()))),
            _ => Ok(()),
        }
    }
}
