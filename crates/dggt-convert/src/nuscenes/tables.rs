//! The nuScenes devkit tables a converter needs (`<root>/<version>/<table>.json`), read once and indexed by
//! token.
//!
//! Conventions (nuScenes schema): `translation` in metres, `rotation` a quaternion in **w, x, y, z** order;
//! `calibrated_sensor` maps sensor -> ego, `ego_pose` ego -> global, `sample_annotation` box -> global; timestamps
//! in microseconds; annotation `size` is **width, length, height**. `ego_pose` has one row per `sample_data` (the
//! pose at that sensor's own time). A quaternion whose norm is not 1 (within 1e-3) or that is not finite is an
//! error naming the table and row.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use dggt_geom::frames::Frame;
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{QuatWxyz, Rigid};
use serde::Deserialize;
use serde::de::DeserializeOwned;

use crate::error::{ConvertError, Result};

/// A nuScenes release: the folder of devkit tables under the data root. The official ones by name, any other
/// folder (a custom split, say) as [`NuScenesVersion::Other`]; either is read when its folder holds the tables.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum NuScenesVersion {
    #[default]
    Mini,
    Trainval,
    Test,
    /// Another folder name (a single path component).
    Other(String),
}

impl NuScenesVersion {
    /// The official releases.
    pub const KNOWN: [NuScenesVersion; 3] = [Self::Mini, Self::Trainval, Self::Test];

    pub fn folder(&self) -> &str {
        match self {
            Self::Mini => "v1.0-mini",
            Self::Trainval => "v1.0-trainval",
            Self::Test => "v1.0-test",
            Self::Other(name) => name,
        }
    }

    /// The folder of this version's tables under the data root `root`, which must exist.
    pub fn tables_folder(&self, root: &Path) -> Result<PathBuf> {
        let dir = root.join(self.folder());
        if dir.is_dir() {
            return Ok(dir);
        }
        let found = version_folders(root);
        let holds = if found.is_empty() { "no version folder".to_string() } else { found.join(", ") };
        let detail = format!(
            "no such nuScenes version folder: the data root {} holds {holds} (a folder with scene.json)",
            root.display()
        );
        Err(ConvertError::io(&dir, std::io::Error::new(std::io::ErrorKind::NotFound, detail)))
    }
}

impl std::str::FromStr for NuScenesVersion {
    type Err = ConvertError;

    /// An official release by name, or any other plain folder name.
    fn from_str(name: &str) -> std::result::Result<Self, ConvertError> {
        if let Some(known) = Self::KNOWN.into_iter().find(|v| v.folder() == name) {
            return Ok(known);
        }
        let mut components = Path::new(name).components();
        match (components.next(), components.next()) {
            (Some(std::path::Component::Normal(_)), None) => Ok(Self::Other(name.to_owned())),
            _ => Err(ConvertError::VersionName { name: name.to_owned() }),
        }
    }
}

/// The folders under `root` that hold a scene table, sorted.
fn version_folders(root: &Path) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(root) else { return Vec::new() };
    let mut names: Vec<String> = entries
        .filter_map(|entry| entry.ok())
        .filter(|entry| entry.path().join("scene.json").is_file())
        .map(|entry| entry.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[derive(Debug, Clone, Deserialize)]
pub struct SceneRow {
    pub token: String,
    pub name: String,
    pub log_token: String,
    pub first_sample_token: String,
    pub nbr_samples: usize,
}

#[derive(Debug, Clone, Deserialize)]
pub struct SampleRow {
    pub token: String,
    pub timestamp: i64,
    pub scene_token: String,
    /// The next sample's token, empty at the scene's end.
    pub next: String,
}

#[derive(Debug, Clone, Deserialize)]
pub struct SampleDataRow {
    pub token: String,
    pub sample_token: String,
    pub ego_pose_token: String,
    pub calibrated_sensor_token: String,
    /// Relative to the data root.
    pub filename: String,
    pub timestamp: i64,
    pub is_key_frame: bool,
    /// The channel's next reading's token, empty at the log's end.
    pub next: String,
    /// Image size in pixels (0 for lidar rows).
    pub width: u32,
    pub height: u32,
}

/// A pose row: `translation` and `rotation` (w, x, y, z).
#[derive(Debug, Clone, Deserialize)]
pub struct PoseRow {
    pub token: String,
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
}

#[derive(Debug, Clone, Deserialize)]
pub struct CalibratedSensorRow {
    pub token: String,
    pub sensor_token: String,
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
    /// 3x3 for cameras, empty for other sensors.
    #[serde(default)]
    pub camera_intrinsic: Vec<Vec<f64>>,
}

#[derive(Debug, Clone, Deserialize)]
pub struct SensorRow {
    pub token: String,
    pub channel: String,
}

#[derive(Debug, Clone, Deserialize)]
pub struct AnnotationRow {
    pub token: String,
    pub sample_token: String,
    pub instance_token: String,
    pub translation: [f64; 3],
    /// Width, length, height in metres.
    pub size: [f64; 3],
    pub rotation: [f64; 4],
}

#[derive(Debug, Clone, Deserialize)]
pub struct InstanceRow {
    pub token: String,
    pub category_token: String,
}

/// The drive a scene was cut from.
#[derive(Debug, Clone, Deserialize)]
pub struct LogRow {
    pub token: String,
    /// e.g. `singapore-onenorth`, `boston-seaport`.
    pub location: String,
}

#[derive(Debug, Clone, Deserialize)]
pub struct CategoryRow {
    pub token: String,
    pub name: String,
}

/// One table's rows by token, and where they came from (for errors).
#[derive(Debug)]
pub struct Table<Row> {
    pub path: PathBuf,
    pub rows: Vec<Row>,
    by_token: HashMap<String, usize>,
}

impl<Row: DeserializeOwned> Table<Row> {
    fn read(dir: &Path, name: &str, token: impl Fn(&Row) -> &str) -> Result<Self> {
        let path = dir.join(format!("{name}.json"));
        let bytes = std::fs::read(&path).map_err(|e| ConvertError::io(&path, e))?;
        let rows: Vec<Row> = serde_json::from_slice(&bytes).map_err(|e| ConvertError::Table {
            path: path.clone(),
            expected: format!("a JSON array of `{name}` rows"),
            found: e.to_string(),
        })?;
        let by_token = rows.iter().enumerate().map(|(i, row)| (token(row).to_owned(), i)).collect();
        Ok(Self { path, rows, by_token })
    }
}

impl<Row> Table<Row> {
    /// The row with `token`, or an error saying which row of which table pointed at it.
    pub fn get(&self, token: &str, referrer: &str) -> Result<&Row> {
        self.by_token.get(token).map(|&i| &self.rows[i]).ok_or_else(|| ConvertError::Table {
            path: self.path.clone(),
            expected: format!("a row with token `{token}` ({referrer})"),
            found: "none".into(),
        })
    }

    /// An error about a row of this table.
    pub fn error(&self, token: &str, expected: impl std::fmt::Display, found: impl Into<String>) -> ConvertError {
        ConvertError::Table {
            path: self.path.clone(),
            expected: format!("row `{token}`: {expected}"),
            found: found.into(),
        }
    }
}

/// Largest accepted deviation of a stored quaternion's norm from 1.
const UNIT_TOLERANCE: f64 = 1e-3;

impl<Row> Table<Row> {
    /// The rigid `To <- From` transform of a row's `rotation` (w, x, y, z) and `translation`.
    pub fn rigid<To: Frame, From: Frame>(
        &self,
        token: &str,
        rotation: [f64; 4],
        translation: [f64; 3],
    ) -> Result<Rigid<To, From>> {
        let what =
            format!("a unit quaternion (w, x, y, z) and a finite translation: a rigid {} <- {}", To::NAME, From::NAME);
        let norm = DQuat::from_array([rotation[1], rotation[2], rotation[3], rotation[0]]).length();
        if !norm.is_finite() || (norm - 1.0).abs() > UNIT_TOLERANCE {
            return Err(self.error(token, what, format!("rotation {rotation:?} (norm {norm:.6})")));
        }
        let unit = QuatWxyz(rotation).to_rotation().map_err(|e| self.error(token, &what, e.to_string()))?;
        Rigid::from_rotation_translation(unit, DVec3::from_array(translation))
            .map_err(|e| self.error(token, &what, format!("translation {translation:?}: {e}")))
    }
}

/// The scene names of the `scene` table of `version` under the data root `root`, in table order.
pub fn scene_names(root: &Path, version: &NuScenesVersion) -> Result<Vec<String>> {
    let table = Table::read(&version.tables_folder(root)?, "scene", |r: &SceneRow| &r.token)?;
    Ok(table.rows.into_iter().map(|row| row.name).collect())
}

/// Every table the converter reads.
#[derive(Debug)]
pub struct Tables {
    pub root: PathBuf,
    pub scene: Table<SceneRow>,
    pub sample: Table<SampleRow>,
    pub sample_data: Table<SampleDataRow>,
    pub ego_pose: Table<PoseRow>,
    pub calibrated_sensor: Table<CalibratedSensorRow>,
    pub sensor: Table<SensorRow>,
    pub sample_annotation: Table<AnnotationRow>,
    pub instance: Table<InstanceRow>,
    pub category: Table<CategoryRow>,
    pub log: Table<LogRow>,
    /// Key-frame `sample_data` rows by (sample token, sensor channel).
    key_frames: HashMap<(String, String), usize>,
    /// Annotation rows by sample token, in table order.
    annotations_of_sample: HashMap<String, Vec<usize>>,
}

impl Tables {
    /// Reads the tables of `version` under the data root `root`.
    pub fn read(root: &Path, version: &NuScenesVersion) -> Result<Self> {
        let dir = version.tables_folder(root)?;
        let mut tables = Self {
            root: root.to_owned(),
            scene: Table::read(&dir, "scene", |r: &SceneRow| &r.token)?,
            sample: Table::read(&dir, "sample", |r: &SampleRow| &r.token)?,
            sample_data: Table::read(&dir, "sample_data", |r: &SampleDataRow| &r.token)?,
            ego_pose: Table::read(&dir, "ego_pose", |r: &PoseRow| &r.token)?,
            calibrated_sensor: Table::read(&dir, "calibrated_sensor", |r: &CalibratedSensorRow| &r.token)?,
            sensor: Table::read(&dir, "sensor", |r: &SensorRow| &r.token)?,
            sample_annotation: Table::read(&dir, "sample_annotation", |r: &AnnotationRow| &r.token)?,
            instance: Table::read(&dir, "instance", |r: &InstanceRow| &r.token)?,
            category: Table::read(&dir, "category", |r: &CategoryRow| &r.token)?,
            log: Table::read(&dir, "log", |r: &LogRow| &r.token)?,
            key_frames: HashMap::new(),
            annotations_of_sample: HashMap::new(),
        };
        tables.index()?;
        Ok(tables)
    }

    fn index(&mut self) -> Result<()> {
        for (i, data) in self.sample_data.rows.iter().enumerate().filter(|(_, d)| d.is_key_frame) {
            let referrer = format!("sample_data `{}`", data.token);
            let calibration = self.calibrated_sensor.get(&data.calibrated_sensor_token, &referrer)?;
            let sensor =
                self.sensor.get(&calibration.sensor_token, &format!("calibrated_sensor `{}`", calibration.token))?;
            self.key_frames.insert((data.sample_token.clone(), sensor.channel.clone()), i);
        }
        for (i, annotation) in self.sample_annotation.rows.iter().enumerate() {
            self.annotations_of_sample.entry(annotation.sample_token.clone()).or_default().push(i);
        }
        Ok(())
    }

    /// The key-frame `sample_data` of `channel` in `sample`.
    pub fn key_frame(&self, sample: &SampleRow, channel: &str) -> Result<&SampleDataRow> {
        let index = self.key_frames.get(&(sample.token.clone(), channel.to_owned())).ok_or_else(|| {
            self.sample_data.error(
                &sample.token,
                format!("a key-frame row of channel {channel} for sample `{}`", sample.token),
                "none",
            )
        })?;
        Ok(&self.sample_data.rows[*index])
    }

    /// The annotations of `sample`.
    pub fn annotations(&self, sample: &SampleRow) -> impl Iterator<Item = &AnnotationRow> {
        self.annotations_of_sample.get(&sample.token).into_iter().flatten().map(|&i| &self.sample_annotation.rows[i])
    }

    /// The samples of scene number `index` (position in the scene table), in time order.
    pub fn scene_samples(&self, index: usize) -> Result<(&SceneRow, Vec<&SampleRow>)> {
        let scene = self.scene.rows.get(index).ok_or_else(|| ConvertError::Table {
            path: self.scene.path.clone(),
            expected: format!("a scene number {index}"),
            found: format!("{} scenes", self.scene.rows.len()),
        })?;
        let mut samples = Vec::with_capacity(scene.nbr_samples);
        let mut token = scene.first_sample_token.as_str();
        let mut referrer = format!("scene `{}` first_sample_token", scene.token);
        while !token.is_empty() {
            let sample = self.sample.get(token, &referrer)?;
            if sample.scene_token != scene.token || samples.len() > self.sample.rows.len() {
                return Err(self.sample.error(
                    token,
                    format!("a sample of scene `{}`", scene.token),
                    "another scene's",
                ));
            }
            samples.push(sample);
            referrer = format!("sample `{token}` next");
            token = &sample.next;
        }
        if samples.is_empty() {
            return Err(self.scene.error(&scene.token, "a first sample", "an empty first_sample_token"));
        }
        Ok((scene, samples))
    }

    /// The readings of `first`'s channel from `first` on, following `next`.
    pub fn channel_chain<'a>(&'a self, first: &'a SampleDataRow) -> Result<Vec<&'a SampleDataRow>> {
        let mut chain = vec![first];
        let mut current = first;
        while !current.next.is_empty() {
            if chain.len() > self.sample_data.rows.len() {
                return Err(self.sample_data.error(&current.token, "a `next` chain that ends", "a cycle"));
            }
            current = self.sample_data.get(&current.next, &format!("sample_data `{}` next", current.token))?;
            chain.push(current);
        }
        Ok(chain)
    }

    /// Where a `sample_data` row's file is: its `filename` under the data root, which the tables may not lead
    /// out of ([`dggt_data::confined`]); a file named as a JPEG must start as one, since it is copied into the
    /// export as it is. Either is an error naming the table, the row and the field.
    pub fn file_of(&self, data: &SampleDataRow) -> Result<PathBuf> {
        let path = dggt_data::confined::confined_path(&self.root, Path::new(&data.filename)).map_err(|escape| {
            self.sample_data.error(&data.token, "a `filename` naming a file under the data root", escape.to_string())
        })?;
        let named_jpeg = Path::new(&data.filename)
            .extension()
            .is_some_and(|extension| extension.eq_ignore_ascii_case("jpg") || extension.eq_ignore_ascii_case("jpeg"));
        if named_jpeg
            && let Some(start) = first_bytes(&path)
            && !start.starts_with(&JPEG_MAGIC)
        {
            let found = format!("{} starting with {start:02x?}", path.display());
            return Err(self.sample_data.error(&data.token, "a `filename` naming a JPEG (ff d8 ff ...)", found));
        }
        Ok(path)
    }
}

/// The first bytes of every JPEG file (start of image, then a marker).
const JPEG_MAGIC: [u8; 3] = [0xff, 0xd8, 0xff];

/// Up to the first three bytes of `path`; `None` when it cannot be read (reading it whole then names why).
fn first_bytes(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read;
    let mut start = Vec::with_capacity(JPEG_MAGIC.len());
    std::fs::File::open(path).ok()?.take(JPEG_MAGIC.len() as u64).read_to_end(&mut start).ok()?;
    Some(start)
}
