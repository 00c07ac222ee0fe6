//! Pairs files: rendered pairs written to disk, and read back as training needs them.
//!
//! A pairs file ([`write_pairs`]) is safetensors: `render`, `target` and `reference`, each `[N, 3, H, W]`
//! float32 RGB in [0, 1], and metadata `views`: a JSON list of `[frame, camera]` per pair (positions in the
//! scene). Many samples' pairs may instead go to a folder of such files, one per sample ([`shard_path`]),
//! written as each sample is rendered so that memory stays bounded and a stopped run resumes.
//!
//! [`PairFiles`] reads a pairs file or a folder of shards: it is indexed by its headers alone, and each pair is
//! read when a step or the validation draws it, so training on the pairs of hundreds of scenes holds one batch
//! of them in memory. Every file is checked when indexed: its `views` metadata, and `render`, `target` and `reference` as float32
//! `[N, 3, H, W]` with one `N` per file (one per view) and one `H x W` for the whole source (a batch takes
//! pairs of one size). A pair's values are checked when read: a value outside [0, 1] or not a number is an
//! error naming the file, the tensor and the pair.

use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use dggt_model::safetensors_file::SafetensorsFile;

use crate::error::{PairKind, RefineTrainError};
use crate::pair::{Image, Pair, RenderedPair, unit_values};

/// The tensors of a pairs file, in this order.
const TENSORS: [&str; 3] = ["render", "target", "reference"];
/// The metadata entry naming each pair's view.
const VIEWS_KEY: &str = "views";

/// The pairs of a pairs file or of a folder of shards, in file-name order, read one at a time.
#[derive(Debug, Clone)]
pub struct PairFiles {
    files: Vec<PairFile>,
    /// The index of each file's first pair among all of them.
    starts: Vec<usize>,
    count: usize,
    height: usize,
    width: usize,
}

#[derive(Debug, Clone)]
struct PairFile {
    path: PathBuf,
    /// `[frame, camera]` of each pair, from the file's metadata.
    views: Vec<[usize; 2]>,
    /// Where `render`, `target` and `reference` ([`TENSORS`]) begin in the file, checked when indexed.
    starts: [u64; 3],
}

impl PairFiles {
    /// Indexes the pairs file `path`, or every `.safetensors` file of the folder `path` in name order.
    pub fn open(path: &Path) -> Result<Self, RefineTrainError> {
        let paths = if path.is_dir() { shard_files(path)? } else { vec![path.to_path_buf()] };
        let (mut files, mut starts, mut count, mut size) = (Vec::new(), Vec::new(), 0, None);
        for path in paths {
            let (file, file_size) = index_file(&path)?;
            match size {
                Some((height, width)) if (height, width) != file_size => {
                    let detail = format!("pairs of {}x{} among pairs of {height}x{width}", file_size.0, file_size.1);
                    return Err(RefineTrainError::PairFile { path, detail });
                }
                _ => size = Some(file_size),
            }
            starts.push(count);
            count += file.views.len();
            files.push(file);
        }
        let (height, width) = size.unwrap_or_default();
        Ok(Self { files, starts, count, height, width })
    }

    /// The number of pairs.
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Pair `index` (of [`Self::len`]) and the view it shows, read from its file at the byte ranges its
    /// indexing checked.
    pub fn read(&self, index: usize) -> Result<RenderedPair, RefineTrainError> {
        if index >= self.count {
            return Err(RefineTrainError::NoSuchPair { kind: PairKind::Any, index, count: self.count });
        }
        let position = self.starts.partition_point(|&start| start <= index) - 1;
        let file = &self.files[position];
        let at = index - self.starts[position];
        let mut open =
            File::open(&file.path).map_err(|source| RefineTrainError::Io { path: file.path.clone(), source })?;
        let mut read = |k: usize| self.read_image(&mut open, file, k, at);
        let (render, target, reference) = (read(0)?, read(1)?, read(2)?);
        let [frame, camera] = file.views[at];
        Ok(RenderedPair { pair: Pair { render, target, reference: Some(reference) }, frame, camera })
    }

    /// Every pair, in order.
    pub fn read_all(&self) -> Result<Vec<RenderedPair>, RefineTrainError> {
        (0..self.count).map(|index| self.read(index)).collect()
    }

    /// Image `at` of tensor `TENSORS[tensor]` of `file` (open as `open`), checked to lie in [0, 1].
    fn read_image(
        &self,
        open: &mut File,
        file: &PairFile,
        tensor: usize,
        at: usize,
    ) -> Result<Image, RefineTrainError> {
        let (height, width) = (self.height, self.width);
        let mut bytes = vec![0u8; 3 * height * width * 4];
        let invalid = |detail: String| RefineTrainError::PairFile {
            path: file.path.clone(),
            detail: format!("tensor '{}', pair {at}: {detail}", TENSORS[tensor]),
        };
        open.seek(SeekFrom::Start(file.starts[tensor] + (at * bytes.len()) as u64))
            .and_then(|_| open.read_exact(&mut bytes))
            .map_err(|e| invalid(format!("not readable: {e}")))?;
        Ok(Image { height, width, values: unit_values(&bytes, invalid)? })
    }
}

/// The `.safetensors` files of a folder of shards, in name order; none is an error naming the folder, and so is
/// a symbolic link among them that leads out of the folder ([`dggt_data::confined`]).
fn shard_files(dir: &Path) -> Result<Vec<PathBuf>, RefineTrainError> {
    let io = |source| RefineTrainError::Io { path: dir.into(), source };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let name = entry.map_err(io)?.file_name();
        if Path::new(&name).extension().is_some_and(|e| e == "safetensors") {
            let file = dggt_data::confined::confined_path(dir, Path::new(&name)).map_err(|escape| {
                RefineTrainError::PairFile { path: dir.into(), detail: format!("a shard outside the folder: {escape}") }
            })?;
            files.push(file);
        }
    }
    if files.is_empty() {
        let detail = "a folder without pair files (.safetensors)".into();
        return Err(RefineTrainError::PairFile { path: dir.into(), detail });
    }
    files.sort();
    Ok(files)
}

/// One pairs file's views and its pairs' size, from its header (see the module's doc for the checks).
fn index_file(path: &Path) -> Result<(PairFile, (usize, usize)), RefineTrainError> {
    let invalid = |detail: String| RefineTrainError::PairFile { path: path.into(), detail };
    let file = SafetensorsFile::open(path)?;
    let views: Vec<[usize; 2]> = file
        .metadata
        .get(VIEWS_KEY)
        .and_then(|v| serde_json::from_str(v).ok())
        .ok_or_else(|| invalid(format!("metadata `{VIEWS_KEY}` missing or not a list of [frame, camera]")))?;
    let (mut size, mut starts) = (None, [0; 3]);
    for (k, name) in TENSORS.into_iter().enumerate() {
        let entry = file.entry(name)?;
        if entry.dtype != "F32" {
            return Err(invalid(format!("tensor '{name}' is {}, expected F32", entry.dtype)));
        }
        let tensor_size = match entry.shape.as_slice() {
            &[n, 3, height, width] if n == views.len() => (height, width),
            shape => {
                return Err(invalid(format!(
                    "tensor '{name}' has shape {shape:?}, expected [{}, 3, H, W] (one image per view)",
                    views.len()
                )));
            }
        };
        if size.is_some_and(|size| size != tensor_size) {
            return Err(invalid(format!("tensor '{name}' differs in size from the others")));
        }
        size = Some(tensor_size);
        starts[k] = file.byte_range(name)?.start;
    }
    Ok((PairFile { path: path.to_path_buf(), views, starts }, size.expect("three tensors checked")))
}

/// Writes `pairs` (all of one size, each with a reference) to `path` (see the module's doc), atomically.
pub fn write_pairs(pairs: &[RenderedPair], path: &Path) -> Result<(), RefineTrainError> {
    let invalid = |detail: String| RefineTrainError::PairFile { path: path.into(), detail };
    let first = pairs.first().ok_or_else(|| invalid("no pairs to write".into()))?;
    let (height, width) = (first.pair.render.height, first.pair.render.width);
    let mut columns: [Vec<u8>; 3] = Default::default();
    for rendered in pairs {
        let Pair { render, target, reference } = &rendered.pair;
        let reference =
            reference.as_ref().ok_or_else(|| invalid(format!("frame {} has no reference", rendered.frame)))?;
        for (column, image) in columns.iter_mut().zip([render, target, reference]) {
            if (image.height, image.width) != (height, width) {
                return Err(invalid(format!(
                    "frame {}: {}x{} among {height}x{width} images",
                    rendered.frame, image.height, image.width
                )));
            }
            column.extend(image.values.iter().flat_map(|v| v.to_le_bytes()));
        }
    }
    let shape = vec![pairs.len(), 3, height, width];
    let views = TENSORS.iter().zip(&columns).map(|(name, bytes)| {
        let view =
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes).expect("sizes agree");
        (name.to_string(), view)
    });
    let frames: Vec<[usize; 2]> = pairs.iter().map(|p| [p.frame, p.camera]).collect();
    let metadata = HashMap::from([(VIEWS_KEY.to_string(), serde_json::to_string(&frames).expect("numbers serialise"))]);
    let file = safetensors::serialize(views, Some(metadata)).map_err(|e| invalid(e.to_string()))?;
    dggt_data::io::write_atomically(path, &file).map_err(|e| invalid(e.to_string()))
}

/// The file of sample `sample`'s pairs in a folder of pair shards.
pub fn shard_path(dir: &Path, sample: u64) -> PathBuf {
    dir.join(format!("sample-{sample:06}.safetensors"))
}
