"""Compares the tensors of two burn-pack (`.bpk`) files.

usage: bpk_digest.py names|ids A.bpk B.bpk
  names: the same tensors under the same names (dtype, shape and bytes);
  ids:   the same multiset of tensors whatever their names (an optimiser's state is keyed by parameter ids that
         are drawn at random each run).

A burn-pack file is the magic `NRUB`, a 2-byte version, a 4-byte little-endian header length, a CBOR header
(`tensors`: name -> dtype, shape, data_offsets) and the data section, aligned to 256 bytes after the header.
"""
import hashlib
import struct
import sys

import cbor2

ALIGNMENT = 256


def tensors(path, keep_names):
    data = open(path, 'rb').read()
    if data[:4] != b'NRUB':
        sys.exit(f'{path}: not a burn-pack file')
    header_len = struct.unpack('<I', data[6:10])[0]
    header = cbor2.loads(data[10:10 + header_len])
    entries = header['tensors']
    end = 10 + header_len
    used = max(t['data_offsets'][1] for t in entries.values())
    start = end if len(data) - end == used else (end + ALIGNMENT - 1) // ALIGNMENT * ALIGNMENT
    rows = []
    for name, t in entries.items():
        first, last = t['data_offsets']
        digest = hashlib.sha256(data[start + first:start + last]).hexdigest()
        rows.append((name if keep_names else '', str(t['dtype']), tuple(t['shape']), digest))
    return sorted(rows)


if __name__ == '__main__':
    mode, a, b = sys.argv[1:4]
    keep = mode == 'names'
    same = tensors(a, keep) == tensors(b, keep)
    print(('same' if same else 'DIFFERENT'), len(tensors(a, keep)), 'tensors')
    sys.exit(0 if same else 1)
