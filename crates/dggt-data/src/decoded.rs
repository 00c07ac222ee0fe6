//! Decoded, preprocessed images and masks kept in memory between samples, so that a run drawing the same views
//! again and again (one scene of a few dozen frames, sampled for a thousand steps) decodes each file once.
//!
//! Bounded by a byte budget: once it is full, files not yet kept are decoded every time they are drawn, as without
//! the cache. Only successful decodes are kept, so a corrupt file is reported every time it is drawn. Keys are the
//! files' paths; a cache belongs to one stream, so one preprocessing.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::Result;
use crate::preprocess::{BinaryMask, PlanarImage};

/// Images and masks decoded and preprocessed, by file.
#[derive(Debug)]
pub struct DecodedViews {
    budget_bytes: usize,
    kept: Mutex<Kept>,
}

#[derive(Debug, Default)]
struct Kept {
    bytes: usize,
    images: HashMap<PathBuf, PlanarImage>,
    masks: HashMap<PathBuf, BinaryMask>,
}

impl DecodedViews {
    /// A cache that keeps at most `budget_bytes` of pixels.
    pub fn new(budget_bytes: usize) -> Self {
        Self { budget_bytes, kept: Mutex::new(Kept::default()) }
    }

    /// A cache that keeps nothing: every view is decoded each time.
    pub fn none() -> Self {
        Self::new(0)
    }

    /// Bytes of pixels kept.
    pub fn bytes(&self) -> usize {
        self.lock().bytes
    }

    /// The image of `path`, decoded by `decode` unless it is kept.
    pub(crate) fn image(&self, path: &Path, decode: impl FnOnce() -> Result<PlanarImage>) -> Result<PlanarImage> {
        if let Some(image) = self.lock().images.get(path) {
            return Ok(image.clone());
        }
        let image = decode()?;
        self.keep(path, &image, size_of_val(image.data.as_slice()), |kept| &mut kept.images);
        Ok(image)
    }

    /// The mask of `path`, decoded by `decode` unless it is kept.
    pub(crate) fn mask(&self, path: &Path, decode: impl FnOnce() -> Result<BinaryMask>) -> Result<BinaryMask> {
        if let Some(mask) = self.lock().masks.get(path) {
            return Ok(mask.clone());
        }
        let mask = decode()?;
        self.keep(path, &mask, mask.data.len(), |kept| &mut kept.masks);
        Ok(mask)
    }

    fn keep<T: Clone>(
        &self,
        path: &Path,
        value: &T,
        bytes: usize,
        map: impl FnOnce(&mut Kept) -> &mut HashMap<PathBuf, T>,
    ) {
        let mut kept = self.lock();
        if kept.bytes + bytes > self.budget_bytes {
            return;
        }
        if map(&mut kept).insert(path.to_path_buf(), value.clone()).is_none() {
            kept.bytes += bytes;
        }
    }

    /// The kept views; a worker that panicked while holding the lock left them whole (inserts are single calls).
    fn lock(&self) -> std::sync::MutexGuard<'_, Kept> {
        self.kept.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

#[cfg(test)]
mod tests {
    use dggt_geom::ImageSize;

    use super::*;
    use crate::error::DataError;

    fn image(value: f32) -> PlanarImage {
        PlanarImage { size: ImageSize { width: 2, height: 1 }, data: vec![value; 6] }
    }

    #[test]
    fn a_kept_image_is_decoded_once_and_the_budget_bounds_what_is_kept() {
        let cache = DecodedViews::new(2 * 24);
        let mut decodes = 0;
        for round in 0..3 {
            for (index, file) in ["a.jpg", "b.jpg", "c.jpg"].into_iter().enumerate() {
                let value = (10 * index + round) as f32;
                let got = cache
                    .image(Path::new(file), || {
                        decodes += 1;
                        Ok(image(value))
                    })
                    .unwrap();
                // Kept files return what their first decode gave; the one past the budget is decoded afresh.
                let expected = if file == "c.jpg" { value } else { (10 * index) as f32 };
                assert_eq!(got.data[0], expected, "{file} in round {round}");
            }
        }
        assert_eq!(decodes, 3 + 2, "a and b decoded once, c every round");
        assert_eq!(cache.bytes(), 48);
    }

    #[test]
    fn a_failed_decode_is_not_kept() {
        let cache = DecodedViews::new(1 << 20);
        let path = Path::new("bad.png");
        let failed = cache.mask(path, || Err(DataError::Config("corrupt".into())));
        assert!(failed.is_err(), "the error reaches the caller");
        let mask = cache.mask(path, || Ok(BinaryMask { size: ImageSize { width: 1, height: 1 }, data: vec![1] }));
        assert_eq!(mask.unwrap().data, vec![1], "decoded again after the failure");
        assert_eq!(cache.bytes(), 1, "the good decode is kept");
    }
}
