"""The study's shards (workflow/Snakefile): one `toolkit compare` CSV per input and replicate,
each with a manifest (JSON) naming the machine it ran on. This module merges them into the one
compare.csv the analysis reads and a shards.csv (input, replicate, host, cpu, ...), and maps
rows to their machine for the report. (The toolkit's summary.json covers every replicate: the
workflow's merge rule runs `toolkit compare --summarize` on the merged CSV.)

    python -m sdfmesh_tools.shards merge --out-csv compare.csv --out-shards shards.csv
        --manifests shards/*/r*.json

Every output is written to a temporary file and renamed, so a merge killed halfway leaves
the old file or none, never a torn one; a shard CSV with a row of the wrong width, or rows
of another input or replicate than its manifest says, is refused with the file and line.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
import tempfile
from pathlib import Path

SHARD_COLUMNS = ["input", "replicate", "host", "cpu", "cores", "threads", "mem_mb", "slurm_job",
                 "started", "finished", "mode", "rows", "csv"]


class ShardError(Exception):
    """A shard that cannot be merged (one line: file, place, problem)."""


def write_atomic(path: str | Path, text: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def read_manifest(path: str | Path) -> dict:
    try:
        m = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise ShardError(f"{path}: cannot read the shard manifest: {e}") from e
    for k in ("input", "replicate", "host", "cpu"):
        if k not in m:
            raise ShardError(f"{path}: the shard manifest has no '{k}'")
    return m


def shard_csv_of(manifest_path: str | Path) -> Path:
    """shards/<input>/r<R>.json -> shards/<input>/r<R>.csv"""
    return Path(manifest_path).with_suffix(".csv")


def read_shard(path: Path, manifest: dict) -> tuple[list[str], list[list[str]], str]:
    """Header, rows and the rows' text (bytes as the toolkit wrote them) of one shard CSV,
    checked: whole rows, this shard's input and replicate."""
    try:
        with open(path, newline="") as f:
            text = f.read()
    except OSError as e:
        raise ShardError(f"{path}: cannot read the shard CSV: {e}") from e
    if text and not text.endswith("\n"):
        n = text.count("\n") + 1
        raise ShardError(f"{path}: line {n}: the last row is cut off (no final newline)")
    lines = list(csv.reader(io.StringIO(text, newline="")))
    if not lines:
        raise ShardError(f"{path}: line 1: empty shard CSV (no header)")
    header, rows = lines[0], lines[1:]
    if text.split("\n", 1)[0] != ",".join(header):
        raise ShardError(f"{path}: line 1: the header is not one plain line")
    for col in ("input", "replicate"):
        if col not in header:
            raise ShardError(f"{path}: line 1: no '{col}' column")
    i_in, i_rep = header.index("input"), header.index("replicate")
    for n, r in enumerate(rows, start=2):
        if len(r) != len(header):
            raise ShardError(f"{path}: line {n}: {len(r)} fields, the header has {len(header)}")
        if r[i_in] != manifest["input"] or r[i_rep] != str(manifest["replicate"]):
            raise ShardError(f"{path}: line {n}: a row of {r[i_in]} replicate {r[i_rep]}, but the "
                             f"shard is {manifest['input']} replicate {manifest['replicate']}")
    return header, rows, text.split("\n", 1)[1]


def merge(manifests: list[str | Path], out_csv, out_shards) -> int:
    """Merges the shards named by `manifests` (in that order); returns the number of rows."""
    header: list[str] | None = None
    first = None
    body: list[str] = []
    n_rows = 0
    shard_rows = []
    for mp in manifests:
        m = read_manifest(mp)
        path = shard_csv_of(mp)
        h, rows, text = read_shard(path, m)
        if header is None:
            header, first = h, path
        elif h != header:
            raise ShardError(f"{path}: line 1: the header differs from {first}'s")
        body.append(text)
        n_rows += len(rows)
        shard_rows.append({**{k: m.get(k, "") for k in SHARD_COLUMNS}, "rows": len(rows), "csv": str(path)})
    merged_csv = "" if header is None else ",".join(header) + "\n" + "".join(body)
    s = io.StringIO(newline="")
    dw = csv.DictWriter(s, fieldnames=SHARD_COLUMNS, lineterminator="\n")
    dw.writeheader()
    dw.writerows(shard_rows)
    write_atomic(out_shards, s.getvalue())
    write_atomic(out_csv, merged_csv)
    return n_rows


def read_shards(path: str | Path | None) -> list[dict]:
    if not path:
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def host_of(shards: list[dict]) -> dict[tuple[str, str], str]:
    """{(input, replicate): host} from shards.csv rows."""
    return {(s["input"], str(s["replicate"])): s["host"] for s in shards}


def machines(shards: list[dict]) -> list[dict]:
    """One dict per host: host, cpu, cores, threads, shards, rows, slurm jobs (in first-seen order)."""
    out: dict[str, dict] = {}
    for s in shards:
        h = out.setdefault(s["host"], {"host": s["host"], "cpu": set(), "cores": set(), "threads": set(),
                                       "shards": 0, "rows": 0, "slurm": 0})
        h["cpu"].add(s.get("cpu", ""))
        h["cores"].add(str(s.get("cores", "")))
        h["threads"].add(str(s.get("threads", "")))
        h["shards"] += 1
        h["rows"] += int(s.get("rows") or 0)
        h["slurm"] += 1 if s.get("slurm_job") else 0
    for h in out.values():
        for k in ("cpu", "cores", "threads"):
            h[k] = ", ".join(sorted(h[k] - {""})) or "–"
    return list(out.values())


# Columns that measure time or the process (they differ between any two runs); every other
# column of a compare or scaling CSV is a deterministic function of the input and settings.
TIMING_COLUMNS = frozenset({"build_ms", "frame_ms_median", "frame_ms_min", "frame_ms_max", "fps_median",
                            "mrays_per_s", "frame_ms_samples", "timestamp", "peak_rss_bytes",
                            "primary_ms", "shading_ms"})
# The columns that identify a row of the compare and the scaling CSVs.
KEY_COLUMNS = ("input", "replicate", "repr", "asked_repr", "method", "resolution", "tolerance_px",
               "relaxation", "primitive", "count")


def differences(a_path, b_path, limit: int = 10) -> list[str]:
    """Where two CSVs of the same runs differ outside TIMING_COLUMNS (rows matched by their key
    columns, in any order); empty when they agree."""
    def load(p):
        with open(p, newline="") as f:
            r = csv.DictReader(f)
            return r.fieldnames or [], list(r)
    ha, ra = load(a_path)
    hb, rb = load(b_path)
    if ha != hb:
        return [f"the headers differ: {a_path}: {ha} vs {b_path}: {hb}"]
    key_cols = [c for c in KEY_COLUMNS if c in ha]

    def index(rows, path):
        out = {}
        for n, r in enumerate(rows, start=2):
            k = tuple(r[c] for c in key_cols)
            if k in out:
                raise ShardError(f"{path}: line {n}: the run {k} appears twice")
            out[k] = r
        return out
    ia, ib = index(ra, a_path), index(rb, b_path)
    out = [f"only in {a_path}: {k}" for k in ia if k not in ib] + \
        [f"only in {b_path}: {k}" for k in ib if k not in ia]
    for k in ia.keys() & ib.keys():
        for c in ha:
            if c not in TIMING_COLUMNS and ia[k][c] != ib[k][c]:
                out.append(f"{k}: {c}: {ia[k][c]!r} vs {ib[k][c]!r}")
    if not ia and not ib:
        out.append(f"{a_path} and {b_path} have no rows")
    return out[:limit] + ([f"... and {len(out) - limit} more"] if len(out) > limit else [])


def not_slurm(shards_csv) -> list[str]:
    """The shards of a shards.csv that did not run as a Slurm job (empty slurm_job)."""
    return [f"{s['input']} replicate {s['replicate']}" for s in read_shards(shards_csv) if not s.get("slurm_job")]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sdfmesh_tools.shards", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("merge", help="merge shard CSVs into one compare CSV")
    m.add_argument("--out-csv", required=True)
    m.add_argument("--out-shards", required=True)
    m.add_argument("--manifests", nargs="+", required=True)
    same = sub.add_parser("same", help="two CSVs of the same runs agree in every non-timing column")
    same.add_argument("a")
    same.add_argument("b")
    same_text = sub.add_parser("same-text", help="two files are identical (e.g. hard-case tables)")
    same_text.add_argument("a")
    same_text.add_argument("b")
    cs = sub.add_parser("check-slurm", help="every shard of a shards.csv ran as a Slurm job")
    cs.add_argument("shards")
    a = ap.parse_args(argv)
    try:
        if a.cmd == "merge":
            n = merge(a.manifests, a.out_csv, a.out_shards)
            print(f"merged {len(a.manifests)} shards, {n} rows into {a.out_csv}")
        elif a.cmd == "same":
            diff = differences(a.a, a.b)
            if diff:
                print(f"{a.a} and {a.b} differ in non-timing columns:", *diff, sep="\n  ", file=sys.stderr)
                return 1
            print(f"same: {a.a} and {a.b} agree in every non-timing column")
        elif a.cmd == "same-text":
            if Path(a.a).read_bytes() != Path(a.b).read_bytes():
                print(f"{a.a} and {a.b} differ", file=sys.stderr)
                return 1
            print(f"same: {a.a} and {a.b} are identical")
        else:
            bad = not_slurm(a.shards)
            n = len(read_shards(a.shards))
            if bad or not n:
                print(f"{a.shards}: not Slurm jobs: {', '.join(bad) or 'no shards at all'}", file=sys.stderr)
                return 1
            print(f"slurm: all {n} shards of {a.shards} ran as Slurm jobs")
    except (ShardError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
