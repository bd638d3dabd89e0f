//! A Wavefront OBJ reader with Mitsuba 3's semantics, reporting the line of every error.
//!
//! Our own reader rather than `tobj`: tobj's errors carry no line number (a malformed face in a
//! million-line file was undiagnosable), it reports out-of-range indices only when an object
//! ends, and its index arithmetic overflows in debug builds on indices such as `0` or `-5` when
//! texture coordinates are present.
//!
//! Semantics, as in Mitsuba 3's `obj` shape: all objects and groups of the file form one mesh;
//! `v`, `vt` and `vn` are read (extra components such as `w` or vertex colours are ignored);
//! each face is fan-triangulated; a vertex is one distinct `v/vt/vn` index triple over the whole
//! file, numbered in order of first use. Negative (relative) indices are accepted as well.
//! `o`, `g`, `s`, `usemtl`, `mtllib`, `l`, `p` and unknown statements are ignored, as Mitsuba
//! ignores them.

use crate::limits::shorten;
use std::collections::HashMap;

use glam::{Vec2, Vec3};

/// An OBJ file as one triangle mesh in the file's own coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjMesh {
    /// Vertex positions, one per distinct `v/vt/vn` triple.
    pub positions: Vec<Vec3>,
    /// Unit vertex normals from `vn`, when the faces give them (all faces or none).
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates from `vt`, when any face vertex gives one (those that do not get
    /// `(0, 0)`), with `v` flipped to `1 − v` as Mitsuba's OBJ loader does.
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles as vertex indices, in the file's winding.
    pub indices: Vec<[u32; 3]>,
    /// Per vertex, the 1-based line of its `v` statement, so that a later check on a vertex
    /// (such as the coordinate limit after `to_world`) can point at the line.
    pub lines: Vec<usize>,
}

/// A malformed statement: its 1-based line and what is wrong, naming the offending text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjError {
    /// 1-based line number in the OBJ file.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// `token` for a message: escaped and cut to about 40 characters ([`shorten`]), since a
/// hostile file may hold a megabyte on one line.
fn quote(token: &[u8]) -> String {
    format!("\"{}\"", shorten(&String::from_utf8_lossy(token)))
}

/// One face vertex: 0-based indices into the `v`, `vt` and `vn` lists read so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Corner {
    v: u32,
    vt: Option<u32>,
    vn: Option<u32>,
}

/// Parser state: the attribute lists and the mesh being built.
#[derive(Default)]
struct Reader {
    /// `v` positions with their lines.
    v: Vec<(Vec3, usize)>,
    /// `vt` texture coordinates, as written.
    vt: Vec<Vec2>,
    /// `vn` normals, unit length.
    vn: Vec<Vec3>,
    /// Mesh vertex of each distinct corner: a hash map, so that deduplication is linear in the
    /// file size (Mitsuba's loader hashes the same triple).
    vertices: HashMap<Corner, u32>,
    /// The corners of the mesh vertices, in vertex order.
    corners: Vec<Corner>,
    indices: Vec<[u32; 3]>,
    /// Whether faces give normals, and the line of the first face, once a face has been read.
    with_normals: Option<(bool, usize)>,
}

/// Parses an OBJ file's bytes (any encoding whose statements are ASCII; lines end in `\n` or
/// `\r\n`).
///
/// # Errors
///
/// The first malformed statement, with its line: a number that does not parse or is not
/// finite, a zero normal, a face with fewer than 3 vertices, an index that is 0, out of range or
/// not an integer, or faces of which some give normals and others do not.
///
/// ```
/// use fireflies::render::shapes::obj_file::parse;
///
/// let mesh = parse(b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
/// assert_eq!(mesh.indices, vec![[0, 1, 2], [0, 2, 3]]);
///
/// let err = parse(b"v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap_err();
/// assert_eq!(err.line, 3);
/// assert!(err.message.contains("vertex index 3 is out of range"));
/// ```
pub fn parse(bytes: &[u8]) -> Result<ObjMesh, ObjError> {
    let mut reader = Reader::default();
    // A byte-order mark would otherwise turn the first statement into an unknown one.
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    for (i, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = i.saturating_add(1);
        reader
            .statement(raw, line)
            .map_err(|message| ObjError { line, message })?;
    }
    Ok(reader.finish())
}

/// Reads `count` finite numbers from `tokens`.
fn numbers<'a>(
    tokens: &mut impl Iterator<Item = &'a [u8]>,
    count: usize,
    what: &str,
) -> Result<[f32; 3], String> {
    let mut out = [0.0f32; 3];
    for (k, slot) in out.iter_mut().enumerate().take(count) {
        let Some(token) = tokens.next() else {
            return Err(format!("{what} needs {count} numbers, found {k}"));
        };
        let value = std::str::from_utf8(token)
            .ok()
            .and_then(|text| text.parse::<f32>().ok())
            .ok_or_else(|| format!("{} in a {what} is not a number", quote(token)))?;
        if !value.is_finite() {
            return Err(format!(
                "{} in a {what} is not a finite 32-bit float (largest magnitude {:e})",
                quote(token),
                f32::MAX
            ));
        }
        *slot = value;
    }
    Ok(out)
}

/// A face index (1-based, or negative counting back from the last of `count` elements) as a
/// 0-based index.
fn index(token: &[u8], count: usize, what: &str) -> Result<u32, String> {
    let value = std::str::from_utf8(token)
        .ok()
        .and_then(|text| text.parse::<i64>().ok())
        .ok_or_else(|| format!("{what} index {} is not an integer", quote(token)))?;
    let resolved = if value > 0 {
        usize::try_from(value - 1).ok()
    } else if value < 0 {
        usize::try_from(value.unsigned_abs())
            .ok()
            .and_then(|back| count.checked_sub(back))
    } else {
        return Err(format!("{what} index 0: OBJ indices start at 1"));
    };
    match resolved.filter(|&i| i < count) {
        Some(i) => u32::try_from(i).map_err(|_| format!("{what} index {value} exceeds 2^32")),
        None => Err(format!(
            "{what} index {value} is out of range: {count} defined before this line"
        )),
    }
}

impl Reader {
    /// One line of the file.
    fn statement(&mut self, raw: &[u8], line: usize) -> Result<(), String> {
        let mut tokens = raw
            .split(u8::is_ascii_whitespace)
            .filter(|token| !token.is_empty());
        let Some(keyword) = tokens.next() else {
            return Ok(());
        };
        match keyword {
            b"v" => {
                let [x, y, z] = numbers(&mut tokens, 3, "vertex position")?;
                self.v.push((Vec3::new(x, y, z), line));
            }
            b"vt" => {
                let [u, v, _] = numbers(&mut tokens, 2, "texture coordinate")?;
                self.vt.push(Vec2::new(u, v));
            }
            b"vn" => {
                let [x, y, z] = numbers(&mut tokens, 3, "vertex normal")?;
                let Some(n) = Vec3::new(x, y, z).try_normalize() else {
                    return Err(format!("vertex normal ({x}, {y}, {z}) has zero length"));
                };
                self.vn.push(n);
            }
            b"f" => self.face(tokens, line)?,
            _ => {}
        }
        Ok(())
    }

    /// A face: its corners become mesh vertices, and it is fan-triangulated.
    fn face<'a>(
        &mut self,
        tokens: impl Iterator<Item = &'a [u8]>,
        line: usize,
    ) -> Result<(), String> {
        let mut ids = Vec::new();
        for token in tokens {
            let corner = self.corner(token)?;
            let has_normal = corner.vn.is_some();
            let (first, first_line) = *self.with_normals.get_or_insert((has_normal, line));
            if has_normal != first {
                return Err(format!(
                    "face vertex {} {}, unlike the first face (line {first_line}): either every \
                     face vertex gives a normal or none does",
                    quote(token),
                    if has_normal {
                        "gives a normal"
                    } else {
                        "gives no normal"
                    },
                ));
            }
            let next = self.corners.len();
            let id = match self.vertices.get(&corner) {
                Some(&id) => id,
                None => {
                    let id = u32::try_from(next)
                        .map_err(|_| "more than 2^32 distinct face vertices".to_string())?;
                    self.vertices.insert(corner, id);
                    self.corners.push(corner);
                    id
                }
            };
            ids.push(id);
        }
        if ids.len() < 3 {
            return Err(format!(
                "a face needs at least 3 vertices, this one has {}",
                ids.len()
            ));
        }
        for k in 2..ids.len() {
            self.indices.push([ids[0], ids[k - 1], ids[k]]);
        }
        Ok(())
    }

    /// A face vertex `v`, `v/vt`, `v//vn` or `v/vt/vn`.
    fn corner(&self, token: &[u8]) -> Result<Corner, String> {
        let mut parts = token.split(|&b| b == b'/');
        let v = parts.next().unwrap_or_default();
        let vt = parts.next().filter(|p| !p.is_empty());
        let vn = parts.next().filter(|p| !p.is_empty());
        if parts.next().is_some() {
            return Err(format!(
                "face vertex {} has more than three '/'-separated indices",
                quote(token)
            ));
        }
        Ok(Corner {
            v: index(v, self.v.len(), "vertex")?,
            vt: vt
                .map(|t| index(t, self.vt.len(), "texture coordinate"))
                .transpose()?,
            vn: vn
                .map(|n| index(n, self.vn.len(), "vertex normal"))
                .transpose()?,
        })
    }

    /// The mesh: positions (and normals) of the distinct corners.
    fn finish(self) -> ObjMesh {
        let with_normals = matches!(self.with_normals, Some((true, _)));
        let mut positions = Vec::with_capacity(self.corners.len());
        let mut lines = Vec::with_capacity(self.corners.len());
        let mut normals = Vec::with_capacity(if with_normals { self.corners.len() } else { 0 });
        let with_uvs = self.corners.iter().any(|c| c.vt.is_some());
        let mut uvs = Vec::with_capacity(if with_uvs { self.corners.len() } else { 0 });
        for corner in &self.corners {
            // Indices were checked against the lists when the corner was read.
            let (p, line) = self.v[corner.v as usize];
            positions.push(p);
            lines.push(line);
            if let Some(n) = corner.vn {
                normals.push(self.vn[n as usize]);
            }
            if with_uvs {
                let uv = corner.vt.map_or(Vec2::ZERO, |t| self.vt[t as usize]);
                uvs.push(Vec2::new(uv.x, 1.0 - uv.y));
            }
        }
        ObjMesh {
            positions,
            normals: with_normals.then_some(normals),
            uvs: with_uvs.then_some(uvs),
            indices: self.indices,
            lines,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_fan_and_corners_dedupe() {
        let mesh = parse(b"v 0 0 0\nv 1 0 0\r\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\nf -4 -2 -1\n").unwrap();
        assert_eq!(mesh.positions.len(), 4);
        assert_eq!(mesh.indices, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
        assert_eq!(mesh.lines, vec![1, 2, 3, 4]);
        assert_eq!(mesh.normals, None);
    }

    #[test]
    fn corners_split_by_normal_and_texcoord() {
        let mesh =
            parse(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 2\nvn 0 1 0\nf 1//1 2//1 3//1\nf 1/1/2 2//1 3//1\n")
                .unwrap();
        assert_eq!(mesh.positions.len(), 4);
        assert_eq!(mesh.indices, vec![[0, 1, 2], [3, 1, 2]]);
        let normals = mesh.normals.unwrap();
        assert_eq!(normals[0], Vec3::Z);
        assert_eq!(normals[3], Vec3::Y);
    }

    #[test]
    fn errors_name_the_line_and_the_token() {
        let cases: &[(&[u8], usize, &str)] = &[
            (b"v 0 0 0\nv 1 x 0\n", 2, "\"x\""),
            (b"v 0 0 0\n\nv 1 1e39 0\n", 3, "finite"),
            (b"v 0 0\n", 1, "found 2"),
            (b"vn 0 0 0\n", 1, "zero length"),
            (b"v 0 0 0\nf 1 1\n", 2, "at least 3"),
            (b"v 0 0 0\nf 1 2 1\n", 2, "index 2 is out of range"),
            (b"v 0 0 0\nf 1 0 1\n", 2, "index 0"),
            (b"v 0 0 0\nf 1 -2 1\n", 2, "index -2"),
            (b"v 0 0 0\nf 1/5 1 1\n", 2, "texture coordinate index 5"),
            (
                b"v 0 0 0\nf 1 1 99999999999999999999\n",
                2,
                "not an integer",
            ),
            (b"v 0 0 0\nf 1/1/1/1 1 1\n", 2, "more than three"),
            (
                b"v 0 0 0\nvn 0 0 1\nf 1//1 1//1 1//1\nf 1 1 1\n",
                4,
                "line 3",
            ),
        ];
        for &(text, line, fragment) in cases {
            let err = parse(text).expect_err(&String::from_utf8_lossy(text));
            assert_eq!(err.line, line, "{err:?}");
            assert!(
                err.message.contains(fragment),
                "{fragment:?} not in {err:?}"
            );
        }
    }

    #[test]
    fn long_tokens_are_shortened_in_messages() {
        let mut text = b"v 1 2 ".to_vec();
        text.extend(std::iter::repeat_n(b'9', 100_000));
        text.push(b'x');
        let err = parse(&text).unwrap_err();
        assert!(err.message.len() < 200, "{}", err.message);
    }
}
