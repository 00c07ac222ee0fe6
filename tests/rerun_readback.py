"""Reads a rerun recording back with rerun's own SDK, as a client would, and prints what it holds as JSON:
per entity whether it is static and, per row, its time (nanoseconds), frame and step, each transform's
translation and quaternion, each scalar's values, and the length of every other component (splats per row, one
image, ...).

Usage: python3 tests/rerun_readback.py FILE.rrd
"""

import json
import sys

import pyarrow
import rerun
import rerun.experimental

SKIPPED = ("rerun.controls.RowId", "log_time")
VALUES = ("Transform3D:translation", "Transform3D:quaternion", "Scalars:scalars")
INDICES = ("frame", "step")


def rows(batch):
    columns = {name: batch.column(name) for name in batch.schema.names if name not in SKIPPED}
    for i in range(batch.num_rows):
        row = {}
        for name, column in columns.items():
            if name == "time":
                row["time_ns"] = column.cast("int64")[i].as_py()
            elif name in INDICES:
                row[name] = column[i].as_py()
            elif name in VALUES:
                row[name] = column[i].as_py()
            elif pyarrow.types.is_list(column.type) and column[i].is_valid:
                row[name] = len(column[i].values)
        yield row


def main(path):
    reader = rerun.experimental.RrdReader(path)
    entities = {}
    for chunk in reader.stream():
        entity = entities.setdefault(chunk.entity_path, {"static": chunk.is_static, "rows": []})
        entity["rows"].extend(rows(chunk.to_record_batch()))
    blueprints = len(reader.blueprints())
    print(json.dumps({"rerun_version": rerun.__version__, "blueprints": blueprints, "entities": entities}))


if __name__ == "__main__":
    main(sys.argv[1])
