//! Pairs files read a pair at a time: a file and a folder of shards index by their headers and read back what
//! was written; shards of two sizes, a truncated file and a file whose views disagree with its tensors are
//! errors naming the file; a value outside [0, 1] is found when its pair is read, naming the file, the tensor
//! and the pair, while the other pairs of the file still read.

use std::path::Path;

use dggt_refine_train::pair::RenderedPair;
use dggt_refine_train::pair_files::PairFiles;
use dggt_refine_train::pair_files::{shard_path, write_pairs};
use dggt_refine_train::pairs::{Image, Pair};

fn image(height: usize, width: usize, seed: usize) -> Image {
    let values = (0..3 * height * width).map(|i| ((i * 31 + seed * 17) % 97) as f32 / 96.0).collect();
    Image { height, width, values }
}

fn pairs(count: usize, height: usize, width: usize, first_frame: usize) -> Vec<RenderedPair> {
    (0..count)
        .map(|k| {
            let seed = 3 * (first_frame + k);
            RenderedPair {
                pair: Pair {
                    render: image(height, width, seed),
                    target: image(height, width, seed + 1),
                    reference: Some(image(height, width, seed + 2)),
                },
                frame: first_frame + k,
                camera: k % 2,
            }
        })
        .collect()
}

fn message(path: &Path) -> String {
    PairFiles::open(path).expect_err("refused").to_string()
}

#[test]
fn a_file_and_a_folder_of_shards_read_back_pair_by_pair() {
    let dir = tempfile::tempdir().unwrap();
    let all = pairs(5, 8, 16, 0);
    let file = dir.path().join("pairs.safetensors");
    write_pairs(&all, &file).unwrap();
    let files = PairFiles::open(&file).unwrap();
    assert_eq!(files.len(), 5);
    assert_eq!(files.read(3).unwrap(), all[3]);
    assert!(files.read(5).is_err(), "pair 5 of 5");

    let shards = dir.path().join("shards");
    std::fs::create_dir(&shards).unwrap();
    write_pairs(&all[2..], &shard_path(&shards, 7)).unwrap();
    write_pairs(&all[..2], &shard_path(&shards, 3)).unwrap();
    let files = PairFiles::open(&shards).unwrap();
    assert_eq!(files.len(), 5);
    for (index, expected) in all.iter().enumerate() {
        assert_eq!(&files.read(index).unwrap(), expected, "pair {index} across two shards");
    }
}

#[test]
fn mixed_sizes_truncation_and_mismatched_views_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let shards = dir.path().join("shards");
    std::fs::create_dir(&shards).unwrap();
    write_pairs(&pairs(2, 8, 16, 0), &shard_path(&shards, 0)).unwrap();
    write_pairs(&pairs(2, 16, 16, 2), &shard_path(&shards, 1)).unwrap();
    let error = message(&shards);
    assert!(error.contains("sample-000001") && error.contains("16x16") && error.contains("8x16"), "{error}");

    let file = dir.path().join("cut.safetensors");
    write_pairs(&pairs(2, 8, 16, 0), &file).unwrap();
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() - 100]).unwrap();
    let error = message(&file);
    assert!(error.contains("cut.safetensors") && error.contains("past the end"), "{error}");

    // Two views named for three images per tensor (the metadata's last view blanked out).
    let file = dir.path().join("views.safetensors");
    write_pairs(&pairs(3, 8, 16, 0), &file).unwrap();
    let mut bytes = std::fs::read(&file).unwrap();
    let header_end = 8 + u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header = String::from_utf8(bytes[8..header_end].to_vec()).unwrap();
    let edited = header.replacen(",[2,0]]", "]      ", 1);
    assert_eq!(edited.len(), header.len(), "the edit keeps the header's length: {header}");
    bytes.splice(8..header_end, edited.into_bytes());
    std::fs::write(&file, &bytes).unwrap();
    let error = message(&file);
    assert!(error.contains("views.safetensors") && error.contains("[2, 3, H, W]"), "{error}");
}

#[test]
fn a_value_outside_the_unit_range_is_found_when_its_pair_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let mut all = pairs(3, 8, 16, 0);
    all[1].pair.target.values[5] = 1.5;
    let file = dir.path().join("pairs.safetensors");
    write_pairs(&all, &file).unwrap();
    let files = PairFiles::open(&file).expect("the headers are sound");
    let error = files.read(1).unwrap_err().to_string();
    assert!(error.contains("pairs.safetensors") && error.contains("'target'") && error.contains("pair 1"), "{error}");
    assert!(error.contains("1.5"), "{error}");
    assert_eq!(files.read(0).unwrap(), all[0]);
    assert_eq!(files.read(2).unwrap(), all[2]);
}

#[cfg(unix)]
#[test]
fn a_shard_linked_from_outside_the_folder_is_refused_naming_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let shards = dir.path().join("shards");
    std::fs::create_dir(&shards).unwrap();
    write_pairs(&pairs(2, 8, 16, 0), &shard_path(&shards, 0)).unwrap();
    let outside = dir.path().join("elsewhere.safetensors");
    write_pairs(&pairs(2, 8, 16, 2), &outside).unwrap();
    std::os::unix::fs::symlink(&outside, shard_path(&shards, 1)).unwrap();
    let error = message(&shards);
    assert!(error.contains("shards") && error.contains("leads outside"), "{error}");
    std::fs::remove_file(shard_path(&shards, 1)).unwrap();
    // A link that stays in the folder is a shard like any other.
    std::os::unix::fs::symlink(shard_path(&shards, 0), shard_path(&shards, 1)).unwrap();
    assert_eq!(PairFiles::open(&shards).unwrap().len(), 4);
}
