//! Gaussians as the INRIA 3D Gaussian Splatting PLY: `binary_little_endian 1.0`, one `vertex` element of
//! float32 properties in exactly this order:
//!
//! `x y z nx ny nz f_dc_0 f_dc_1 f_dc_2 opacity scale_0 scale_1 scale_2 rot_0 rot_1 rot_2 rot_3`
//!
//! Values are stored before activation, as the viewers (SuperSplat, Brush, antimatter15) expect: opacity as a
//! logit, scales as natural logs, rotation as a unit quaternion `w x y z`, colour as the degree-0 spherical
//! harmonic coefficient `f_dc = (rgb - 0.5) / C0` with `C0 = 0.28209479`, normals zero. No `f_rest_*`
//! properties are written (SH degree 0); the reader accepts and ignores them.
//!
//! [`GaussianCloud`] holds activated values (linear scales, opacities in `[0, 1]`, RGB), the form the scene
//! assembly works in; the conversion happens here only.

use std::path::Path;

use crate::FormatError;

/// The degree-0 spherical-harmonic constant `1 / (2 sqrt(pi))`.
pub const SH_C0: f32 = 0.282_094_8;

/// Opacities are clamped to `[OPACITY_EPS, 1 - OPACITY_EPS]` before the logit so that it stays finite.
pub const OPACITY_EPS: f32 = 1e-6;

/// Scales are clamped to at least this before the log.
pub const MIN_SCALE: f32 = 1e-12;

/// The property names this writer emits, in order.
pub const INRIA_PROPERTIES: [&str; 17] = [
    "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0",
    "rot_1", "rot_2", "rot_3",
];

/// Activated Gaussians, one entry per Gaussian in every field.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaussianCloud {
    pub means: Vec<[f32; 3]>,
    /// Unit quaternions `w x y z`.
    pub quats_wxyz: Vec<[f32; 4]>,
    /// Linear scales (standard deviations along the rotated axes).
    pub scales: Vec<[f32; 3]>,
    /// Opacity in `[0, 1]`.
    pub opacities: Vec<f32>,
    /// RGB, nominally in `[0, 1]`.
    pub colors: Vec<[f32; 3]>,
}

impl GaussianCloud {
    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Checks that every field has one entry per Gaussian.
    pub fn check(&self) -> Result<(), PlyError> {
        let means = self.means.len();
        let (rotations, scales) = (self.quats_wxyz.len(), self.scales.len());
        let (opacities, colors) = (self.opacities.len(), self.colors.len());
        if [rotations, scales, opacities, colors].iter().any(|&l| l != means) {
            return Err(PlyError::FieldLengths { means, rotations, scales, opacities, colors });
        }
        Ok(())
    }

    /// Appends Gaussian `index` of `other`.
    pub fn push_from(&mut self, other: &GaussianCloud, index: usize) {
        self.means.push(other.means[index]);
        self.quats_wxyz.push(other.quats_wxyz[index]);
        self.scales.push(other.scales[index]);
        self.opacities.push(other.opacities[index]);
        self.colors.push(other.colors[index]);
    }

    /// The 17 stored (pre-activation) values of Gaussian `i`, in [`INRIA_PROPERTIES`] order.
    pub fn stored_values(&self, i: usize) -> [f32; 17] {
        let [x, y, z] = self.means[i];
        let dc = self.colors[i].map(|c| (c - 0.5) / SH_C0);
        let o = self.opacities[i].clamp(OPACITY_EPS, 1.0 - OPACITY_EPS);
        let logit = (o / (1.0 - o)).ln();
        let s = self.scales[i].map(|s| s.max(MIN_SCALE).ln());
        let q = self.quats_wxyz[i];
        let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        let q = if norm > 0.0 && norm.is_finite() { q.map(|v| v / norm) } else { [1.0, 0.0, 0.0, 0.0] };
        [x, y, z, 0.0, 0.0, 0.0, dc[0], dc[1], dc[2], logit, s[0], s[1], s[2], q[0], q[1], q[2], q[3]]
    }
}

/// The PLY header this writer emits for `count` vertices.
pub fn inria_header(count: usize) -> String {
    let mut header = format!("ply\nformat binary_little_endian 1.0\nelement vertex {count}\n");
    for name in INRIA_PROPERTIES {
        header.push_str("property float ");
        header.push_str(name);
        header.push('\n');
    }
    header.push_str("end_header\n");
    header
}

/// Encodes `cloud` as an INRIA-layout binary PLY.
pub fn encode_ply(cloud: &GaussianCloud) -> Result<Vec<u8>, PlyError> {
    cloud.check()?;
    let header = inria_header(cloud.len());
    let mut bytes = Vec::with_capacity(header.len() + cloud.len() * INRIA_PROPERTIES.len() * 4);
    bytes.extend_from_slice(header.as_bytes());
    for i in 0..cloud.len() {
        for value in cloud.stored_values(i) {
            bytes.extend_from_slice(&value.to_le_bytes());
        }
    }
    Ok(bytes)
}

/// Writes `cloud` to `path` as an INRIA-layout binary PLY.
pub fn write_ply(path: &Path, cloud: &GaussianCloud) -> Result<(), FormatError> {
    let bytes = encode_ply(cloud).map_err(|source| FormatError::Ply { path: path.to_owned(), source })?;
    crate::write_file(path, &bytes)
}

/// What is wrong with a cloud to write or with PLY bytes read; [`write_ply`] and [`read_ply`] add the file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlyError {
    #[error(
        "field lengths differ: {means} means, {rotations} rotations, {scales} scales, {opacities} opacities, {colors} colours"
    )]
    FieldLengths { means: usize, rotations: usize, scales: usize, opacities: usize, colors: usize },
    #[error("no `{0}` property")]
    MissingProperty(&'static str),
    #[error("no `end_header` line")]
    NoEndHeader,
    #[error("a header that is not UTF-8")]
    HeaderNotUtf8,
    #[error("the first line is not `ply`")]
    NotPly,
    #[error("no `format` line")]
    NoFormat,
    #[error("no `element vertex` line")]
    NoVertexElement,
    #[error("vertex count `{0}` (not a count, or too large)")]
    VertexCount(String),
    /// A header line this reader does not take (only what this project writes and 3DGS viewers read).
    #[error("header line `{line}`: {what} (only one `vertex` element of float32 properties is read)")]
    Unsupported { line: String, what: String },
    #[error("{count} vertices x {properties} properties = {expected} bytes after the header, found {found}")]
    BodyLength { count: usize, properties: usize, expected: usize, found: usize },
}

/// A binary little-endian PLY with one `vertex` element of float32 properties, as read.
#[derive(Debug, Clone, PartialEq)]
pub struct PlyVertices {
    /// Property names in file order.
    pub properties: Vec<String>,
    pub count: usize,
    /// Row-major: vertex `i`, property `j` at `i * properties.len() + j`.
    pub values: Vec<f32>,
}

impl PlyVertices {
    /// Column of a property, by name.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p == name)
    }

    /// The stored value of property `name` of vertex `i`.
    pub fn value(&self, i: usize, name: &str) -> Option<f32> {
        self.column(name).map(|j| self.values[i * self.properties.len() + j])
    }

    /// The activated Gaussians (inverse of the writer's conversion). Errors name the missing property.
    pub fn to_cloud(&self) -> Result<GaussianCloud, PlyError> {
        let columns = INRIA_PROPERTIES
            .iter()
            .map(|&name| self.column(name).ok_or(PlyError::MissingProperty(name)))
            .collect::<Result<Vec<_>, _>>()?;
        let width = self.properties.len();
        let mut cloud = GaussianCloud::default();
        for i in 0..self.count {
            let v = |k: usize| self.values[i * width + columns[k]];
            cloud.means.push([v(0), v(1), v(2)]);
            cloud.colors.push([v(6), v(7), v(8)].map(|dc| dc * SH_C0 + 0.5));
            cloud.opacities.push(1.0 / (1.0 + (-v(9)).exp()));
            cloud.scales.push([v(10), v(11), v(12)].map(f32::exp));
            cloud.quats_wxyz.push([v(13), v(14), v(15), v(16)]);
        }
        Ok(cloud)
    }
}

/// Parses a binary little-endian PLY holding one `vertex` element of float32 properties (other elements and
/// types are rejected: they are not what this project writes or what the viewers' 3DGS loaders read).
pub fn parse_ply(bytes: &[u8]) -> Result<PlyVertices, PlyError> {
    const END: &[u8] = b"end_header\n";
    let end = bytes.windows(END.len()).position(|w| w == END).ok_or(PlyError::NoEndHeader)? + END.len();
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| PlyError::HeaderNotUtf8)?;
    let mut lines = header.lines();
    if lines.next() != Some("ply") {
        return Err(PlyError::NotPly);
    }
    let mut count = None;
    let mut properties = Vec::new();
    let mut format_seen = false;
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        let unsupported = |what: &str| Err(PlyError::Unsupported { line: line.to_string(), what: what.to_string() });
        match words.as_slice() {
            ["format", "binary_little_endian", "1.0"] => format_seen = true,
            ["format", ..] => return unsupported("a format other than binary_little_endian 1.0"),
            ["comment", ..] | ["obj_info", ..] | ["end_header"] => {}
            ["element", "vertex", n] if count.is_none() => {
                count = Some(n.parse::<usize>().map_err(|_| PlyError::VertexCount(n.to_string()))?);
            }
            ["element", ..] => return unsupported("an element besides the one `vertex` element"),
            ["property", "float", name] if count.is_some() => properties.push(name.to_string()),
            ["property", ..] => return unsupported("a property that is not a vertex float32"),
            [] => {}
            _ => return unsupported("a header line of no known kind"),
        }
    }
    if !format_seen {
        return Err(PlyError::NoFormat);
    }
    let count = count.ok_or(PlyError::NoVertexElement)?;
    let body = &bytes[end..];
    let expected = count.checked_mul(properties.len() * 4).ok_or(PlyError::VertexCount(count.to_string()))?;
    if body.len() != expected {
        return Err(PlyError::BodyLength { count, properties: properties.len(), expected, found: body.len() });
    }
    let values = body.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    Ok(PlyVertices { properties, count, values })
}

/// Reads a PLY written by [`write_ply`] (or any binary float32 vertex PLY).
pub fn read_ply(path: &Path) -> Result<PlyVertices, FormatError> {
    let bytes = crate::read_file(path)?;
    parse_ply(&bytes).map_err(|source| FormatError::Ply { path: path.to_owned(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_values_are_pre_activation() {
        let cloud = GaussianCloud {
            means: vec![[1.0, 2.0, 3.0]],
            quats_wxyz: vec![[2.0, 0.0, 0.0, 0.0]],
            scales: vec![[1.0, std::f32::consts::E, 0.5]],
            opacities: vec![0.5],
            colors: vec![[0.5, 0.5 + SH_C0, 0.0]],
        };
        let v = cloud.stored_values(0);
        assert_eq!(&v[..6], &[1.0, 2.0, 3.0, 0.0, 0.0, 0.0]);
        assert!((v[6]).abs() < 1e-6 && (v[7] - 1.0).abs() < 1e-6 && (v[8] + 0.5 / SH_C0).abs() < 1e-5);
        assert!(v[9].abs() < 1e-6, "logit of 0.5");
        assert!(v[10].abs() < 1e-6 && (v[11] - 1.0).abs() < 1e-6 && (v[12] - 0.5f32.ln()).abs() < 1e-6);
        assert_eq!(&v[13..], &[1.0, 0.0, 0.0, 0.0]);
        // Opacity 0 and 1 stay finite.
        let mut edge = cloud;
        edge.opacities = vec![0.0];
        assert!(edge.stored_values(0)[9].is_finite());
        edge.opacities = vec![1.0];
        assert!(edge.stored_values(0)[9].is_finite());
    }

    #[test]
    fn malformed_files_are_rejected() {
        assert!(parse_ply(b"ply\nformat ascii 1.0\nend_header\n").unwrap_err().to_string().contains("ascii"));
        let mut bytes = encode_ply(&GaussianCloud {
            means: vec![[0.0; 3]],
            quats_wxyz: vec![[1.0, 0.0, 0.0, 0.0]],
            scales: vec![[1.0; 3]],
            opacities: vec![0.5],
            colors: vec![[0.5; 3]],
        })
        .unwrap();
        bytes.pop();
        assert!(parse_ply(&bytes).unwrap_err().to_string().contains("bytes after the header"));
        let mut uneven = GaussianCloud::default();
        uneven.means.push([0.0; 3]);
        assert!(encode_ply(&uneven).is_err());
    }
}
