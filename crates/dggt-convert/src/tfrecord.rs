//! TFRecord framing, read one record at a time so that a segment of a gigabyte never sits in memory whole.
//!
//! A record is `length: u64 LE`, `masked CRC32C of the 8 length bytes: u32 LE`, `payload` (`length` bytes),
//! `masked CRC32C of the payload: u32 LE`. A CRC is masked as `rotate_right(crc, 15) + 0xa282ead8` (wrapping).
//! Both checks are verified; a file ending exactly between records ends the stream, anywhere else is an error.

use std::fs::File;
use std::io::{BufReader, ErrorKind, Read};
use std::path::{Path, PathBuf};

use crate::error::{ConvertError, Result};

const MASK_DELTA: u32 = 0xa282_ead8;
/// Bytes of framing around each payload.
pub const FRAMING_BYTES: u64 = 8 + 4 + 4;
/// Largest payload accepted: a Waymo frame is a few MB; anything near this is a corrupt length field that the
/// length CRC failed to catch.
const MAX_PAYLOAD_BYTES: u64 = 1 << 30;

/// The masked CRC32C that TFRecord stores.
pub fn masked_crc32c(bytes: &[u8]) -> u32 {
    crc32c::crc32c(bytes).rotate_right(15).wrapping_add(MASK_DELTA)
}

/// One record framed as TFRecord (for writing test and benchmark segments).
pub fn frame_record(payload: &[u8]) -> Vec<u8> {
    let length = (payload.len() as u64).to_le_bytes();
    let mut out = Vec::with_capacity(payload.len() + FRAMING_BYTES as usize);
    out.extend_from_slice(&length);
    out.extend_from_slice(&masked_crc32c(&length).to_le_bytes());
    out.extend_from_slice(payload);
    out.extend_from_slice(&masked_crc32c(payload).to_le_bytes());
    out
}

/// Reads the records of one TFRecord file in order, reusing one payload buffer.
pub struct RecordReader {
    path: PathBuf,
    reader: BufReader<File>,
    next_record: usize,
    bytes_read: u64,
    payload: Vec<u8>,
}

impl RecordReader {
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| ConvertError::io(path, e))?;
        Ok(Self {
            path: path.to_owned(),
            reader: BufReader::with_capacity(1 << 20, file),
            next_record: 0,
            bytes_read: 0,
            payload: Vec::new(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of the file consumed so far (for progress).
    pub fn bytes_read(&self) -> u64 {
        self.bytes_read
    }

    /// The next record's index and payload, or `None` at a clean end of file. The payload is valid until the
    /// next call.
    pub fn next_record(&mut self) -> Result<Option<(usize, &[u8])>> {
        let record = self.next_record;
        let mut header = [0u8; 12];
        match read_exact_or_eof(&mut self.reader, &mut header).map_err(|e| ConvertError::io(&self.path, e))? {
            Filled::Nothing => return Ok(None),
            Filled::Partly(n) => return Err(self.framing("a 12-byte record header", format!("{n} bytes"))),
            Filled::Whole => {}
        }
        let length_bytes: [u8; 8] = header[..8].try_into().expect("8 bytes");
        let stored_length_crc = u32::from_le_bytes(header[8..].try_into().expect("4 bytes"));
        let length_crc = masked_crc32c(&length_bytes);
        if stored_length_crc != length_crc {
            return Err(self.framing(
                format!("length CRC {length_crc:#010x}"),
                format!("{stored_length_crc:#010x} (corrupt record header)"),
            ));
        }
        let length = u64::from_le_bytes(length_bytes);
        if length > MAX_PAYLOAD_BYTES {
            return Err(self.framing(format!("a payload of at most {MAX_PAYLOAD_BYTES} bytes"), format!("{length}")));
        }
        self.payload.resize(length as usize + 4, 0);
        match read_exact_or_eof(&mut self.reader, &mut self.payload).map_err(|e| ConvertError::io(&self.path, e))? {
            Filled::Whole => {}
            Filled::Nothing | Filled::Partly(_) => {
                return Err(self.framing(
                    format!("{length} payload bytes and a 4-byte CRC"),
                    "the end of the file (truncated record)",
                ));
            }
        }
        let (payload, crc) = self.payload.split_at(length as usize);
        let stored_crc = u32::from_le_bytes(crc.try_into().expect("4 bytes"));
        let payload_crc = masked_crc32c(payload);
        if stored_crc != payload_crc {
            return Err(ConvertError::Framing {
                path: self.path.clone(),
                record,
                expected: format!("payload CRC {payload_crc:#010x}"),
                found: format!("{stored_crc:#010x} (corrupt payload)"),
            });
        }
        self.next_record += 1;
        self.bytes_read += length + FRAMING_BYTES;
        Ok(Some((record, &self.payload[..length as usize])))
    }

    fn framing(&self, expected: impl Into<String>, found: impl Into<String>) -> ConvertError {
        ConvertError::Framing {
            path: self.path.clone(),
            record: self.next_record,
            expected: expected.into(),
            found: found.into(),
        }
    }
}

enum Filled {
    Nothing,
    Partly(usize),
    Whole,
}

fn read_exact_or_eof(reader: &mut impl Read, buffer: &mut [u8]) -> std::io::Result<Filled> {
    let mut filled = 0;
    while filled < buffer.len() {
        match reader.read(&mut buffer[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(match filled {
        0 if !buffer.is_empty() => Filled::Nothing,
        n if n == buffer.len() => Filled::Whole,
        n => Filled::Partly(n),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_records(dir: &Path, payloads: &[&[u8]]) -> PathBuf {
        let path = dir.join("segment.tfrecord");
        let bytes: Vec<u8> = payloads.iter().flat_map(|p| frame_record(p)).collect();
        std::fs::write(&path, bytes).unwrap();
        path
    }

    fn read_all(path: &Path) -> Result<Vec<Vec<u8>>> {
        let mut reader = RecordReader::open(path)?;
        let mut out = Vec::new();
        while let Some((index, payload)) = reader.next_record()? {
            assert_eq!(index, out.len());
            out.push(payload.to_vec());
        }
        Ok(out)
    }

    #[test]
    fn masked_crc_matches_the_crc32c_check_value() {
        // CRC32C("123456789") = 0xE3069283 (the standard check value), then masked.
        let expected = 0xE306_9283u32.rotate_right(15).wrapping_add(MASK_DELTA);
        assert_eq!(masked_crc32c(b"123456789"), expected);
    }

    #[test]
    fn records_round_trip_including_empty_ones() {
        let dir = tempfile::tempdir().unwrap();
        let path = write_records(dir.path(), &[b"first", b"", b"third record"]);
        let records = read_all(&path).unwrap();
        assert_eq!(records, [b"first".to_vec(), Vec::new(), b"third record".to_vec()]);
    }

    #[test]
    fn every_kind_of_damage_names_the_record() {
        let dir = tempfile::tempdir().unwrap();
        let path = write_records(dir.path(), &[b"first", b"second"]);
        let good = std::fs::read(&path).unwrap();
        let second = (FRAMING_BYTES + 5) as usize;
        type Damage = Box<dyn Fn(&mut Vec<u8>)>;
        let cases: [(&str, Damage); 4] = [
            ("payload CRC", Box::new(move |b| b[second + 12] ^= 0x01)),
            ("length CRC", Box::new(move |b| b[second] ^= 0x01)),
            ("truncated record", Box::new(|b| b.truncate(b.len() - 3))),
            ("12-byte record header", Box::new(move |b| b.truncate(second + 5))),
        ];
        for (what, damage) in cases {
            let mut bytes = good.clone();
            damage(&mut bytes);
            std::fs::write(&path, &bytes).unwrap();
            let message = read_all(&path).unwrap_err().to_string();
            assert!(message.contains("segment.tfrecord") && message.contains("record 1"), "{what}: {message}");
            assert!(message.contains(what), "{what}: {message}");
        }
    }
}
