"""The study workflow (workflow/Snakefile): merging shards (sdfmesh_tools.shards), the report's
machine section, and an interrupted workflow that resumes without repeating finished shards
and without a torn CSV line (real Snakemake, real toolkit)."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sdfmesh_tools import report, shards
from test_study import class_rows

REPO = Path(__file__).resolve().parents[2]
HEADER = "input,class,replicate,repr,method,frame_ms_median,timestamp,note\n"


def make_shard(root: Path, name: str, rep: int, host: str, rows: list[str], tail: str = "") -> Path:
    d = root / "shards" / name
    d.mkdir(parents=True, exist_ok=True)
    (d / f"r{rep}.csv").write_text(HEADER + "".join(r + "\n" for r in rows) + tail)
    m = d / f"r{rep}.json"
    m.write_text(json.dumps({"input": name, "replicate": rep, "host": host, "cpu": f"{host} CPU",
                             "cores": 2, "threads": 2, "mem_mb": 1024, "slurm_job": "",
                             "started": "t0", "finished": "t1", "mode": "--overwrite"}))
    return m


def test_merge_keeps_rows_byte_for_byte_and_records_hosts(tmp_path):
    a = make_shard(tmp_path, "a", 0, "h1", ['a,x,0,sdf,sphere-trace,1.5,T1,"quoted, note"', "a,x,0,mesh,p,2.0,T2,"])
    b = make_shard(tmp_path, "b", 1, "h2", ["b,x,1,sdf,sphere-trace,1.0,T3,"])
    out = tmp_path / "compare.csv"
    n = shards.merge([a, b], out, tmp_path / "shards.csv")
    assert n == 3
    assert out.read_text() == (HEADER + 'a,x,0,sdf,sphere-trace,1.5,T1,"quoted, note"\n'
                               "a,x,0,mesh,p,2.0,T2,\nb,x,1,sdf,sphere-trace,1.0,T3,\n")
    s = shards.read_shards(tmp_path / "shards.csv")
    assert [(r["input"], r["replicate"], r["host"], r["rows"]) for r in s] == [("a", "0", "h1", "2"), ("b", "1", "h2", "1")]
    assert shards.host_of(s) == {("a", "0"): "h1", ("b", "1"): "h2"}
    ms = shards.machines(s)
    assert [(m["host"], m["shards"], m["rows"]) for m in ms] == [("h1", 1, 2), ("h2", 1, 1)]


@pytest.mark.parametrize("tail, rows, message", [
    ("a,x,0,mesh,p,2.", [], "line 2: the last row is cut off"),
    ("", ["a,x,0,mesh,p,2.0"], "line 2: 6 fields, the header has 8"),
    ("", ["b,x,0,mesh,p,2.0,T,"], "line 2: a row of b replicate 0, but the shard is a replicate 0"),
])
def test_merge_refuses_a_bad_shard_and_writes_nothing(tmp_path, capsys, tail, rows, message):
    m = make_shard(tmp_path, "a", 0, "h1", rows, tail)
    out = tmp_path / "compare.csv"
    rc = shards.main(["merge", "--out-csv", str(out), "--out-shards", str(tmp_path / "s.csv"),
                      "--manifests", str(m)])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and str(m.with_suffix(".csv")) in err and err.count("\n") == 1
    assert not out.exists() and not (tmp_path / "s.csv").exists()


def test_differences_ignore_timing_columns_only(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text(HEADER + "a,x,0,sdf,st,1.5,T1,\na,x,0,mesh,p,2.0,T2,\n")
    b.write_text(HEADER + "a,x,0,mesh,p,9.0,T9,\na,x,0,sdf,st,7.5,T8,\n")
    assert shards.differences(a, b) == []
    b.write_text(HEADER + "a,x,0,mesh,p,9.0,T9,\na,x,0,sdf,st,7.5,T8,different\n")
    d = shards.differences(a, b)
    assert len(d) == 1 and "note" in d[0]
    b.write_text(HEADER + "a,x,0,mesh,p,9.0,T9,\n")
    assert any("only in" in x for x in shards.differences(a, b))


def test_two_compare_runs_agree_outside_timing_columns(toolkit, tmp_path):
    """Two processes comparing the same input agree in every column outside TIMING_COLUMNS (what
    tools/slurm-test checks between a Slurm and a local study), so a new timing column of the
    compare CSV must be named there."""
    scene = REPO / "data" / "scenes" / "csg" / "csg_bitten.toml"
    outs = []
    for n in range(2):
        out = tmp_path / f"c{n}.csv"
        r = subprocess.run([str(toolkit), "compare", str(scene), "--width", "24", "--height", "24",
                            "--res", "8", "--csv", str(out)], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        outs.append(out)
    with open(outs[0], newline="") as f:
        header = next(csv.reader(f))
    assert {"primary_ms", "shading_ms", "frame_ms_median"} <= set(header)
    assert shards.differences(*outs, limit=20) == []


def _shard_rows_for(rows, host_by_input_rep):
    return [{"input": i, "replicate": r, "host": h, "cpu": f"{h} cpu", "cores": "2", "threads": "2",
             "rows": "1", "slurm_job": ""} for (i, r), h in host_by_input_rep.items()]


def test_machines_section_says_whether_verdicts_differ():
    # the same class measured on two machines: on "fast" SDF wins 2x, on "slow" mesh wins 3x
    rows_fast = class_rows("smooth", [0.5, 0.45, 0.55, 0.5], seed=1)
    rows_slow = class_rows("smooth", [3.0, 2.5, 3.5, 3.2], seed=2)
    for r in rows_slow:
        r["replicate"] = int(r["replicate"]) + 3
    all_rows = [{k: str(v) for k, v in r.items()} for r in rows_fast + rows_slow]
    hosts = {(r["input"], r["replicate"]): ("fast" if int(r["replicate"]) < 3 else "slow") for r in all_rows}
    text = report.machines_section(all_rows, _shard_rows_for(all_rows, hosts))
    assert "| fast |" in text and "| slow |" in text
    assert "The verdicts differ between machines at: smooth" in text
    # one machine: nothing to compare
    one = {k: "fast" for k in hosts}
    assert "ran on one machine" in report.machines_section(all_rows, _shard_rows_for(all_rows, one))
    # both machines agree
    same = [{**r, "input": r["input"]} for r in all_rows if int(r["replicate"]) < 3]
    split = {(r["input"], r["replicate"]): ("a" if r["replicate"] == "0" else "b") for r in same}
    assert "do not differ" in report.machines_section(same, _shard_rows_for(same, split))


WRAPPER = r"""#!/usr/bin/env bash
# The real toolkit, except for the victim's first run: it runs in full, waits until another
# shard has finished, then cuts its rows back to two whole rows and half a third (as a kill
# in the middle of writing a row leaves them) and hangs until the test kills the workflow.
real=@REAL@; marker=@MARKER@; victim=@VICTIM@
work=""; prev=""
for a in "$@"; do [ "$prev" = --csv ] && work=$a; prev=$a; done
case " $* " in
  *" $victim "*) ;;
  *) exec "$real" "$@" ;;
esac
[ -e "$marker" ] && exec "$real" "$@"
"$real" "$@" || exit $?
cp "$work" "$marker.full"
for _ in $(seq 600); do compgen -G 'shards/*/r0.csv' >/dev/null && break; sleep 0.2; done
{ head -n 3 "$work"; sed -n 4p "$work" | cut -c1-25 | tr -d '\n'; } >"$work.cut"
mv "$work.cut" "$work"
echo $$ >"$marker"
sleep 600
"""


def run_workflow(out: Path, wrapper: Path, inputs: list[str], *, wait=True, unlock=False):
    cmd = [sys.executable, "-m", "snakemake", "compare.csv", "--snakefile", str(REPO / "workflow" / "Snakefile"),
           "--directory", str(out), "--cores", "2", "--rerun-incomplete", "--quiet", "all",
           "--config", f"toolkit={wrapper}", "inputs=" + ",".join(inputs), "res=8,16", "frames=1",
           "size=24", "replicates=1", "sdf_tol=1", "sdf_relax=1", "threads=1", "shard_mem_mb=1024"]
    env = {**os.environ, "PYTHONPATH": str(REPO / "tools")}
    if unlock:
        # a killed engine leaves its lock (as STUDY_RESUME=1 tools/study does)
        subprocess.run(cmd + ["--unlock"], cwd=REPO, env=env, capture_output=True, check=True, timeout=300)
    p = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True, start_new_session=True)
    if wait:
        text = p.communicate(timeout=900)[0]
        assert p.returncode == 0, text[-3000:]
    return p


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_interrupted_workflow_resumes_without_repeats_or_torn_rows(tmp_path, toolkit):
    pytest.importorskip("snakemake")
    inputs = ["data/scenes/smooth/smooth_spheres.toml", "data/scenes/csg/csg_bitten.toml",
              "data/scenes/smooth/smooth_capsules.toml"]
    victim = str(REPO / inputs[1])
    out, marker = tmp_path / "study", tmp_path / "killed-here"
    wrapper = tmp_path / "toolkit"
    wrapper.write_text(WRAPPER.replace("@REAL@", str(toolkit)).replace("@MARKER@", str(marker))
                       .replace("@VICTIM@", victim))
    wrapper.chmod(0o755)

    p = run_workflow(out, wrapper, [str(REPO / i) for i in inputs], wait=False)
    deadline = time.time() + 600
    while not marker.exists() or not marker.read_text().strip():
        assert p.poll() is None, f"the workflow ended before the kill:\n{p.stdout.read()[-3000:]}"
        assert time.time() < deadline, "the victim shard never reached the kill point"
        time.sleep(0.1)
    # a job killed mid-run: kill the whole workflow (engine and jobs) at once
    os.killpg(p.pid, signal.SIGKILL)
    try:
        os.kill(int(marker.read_text()), signal.SIGKILL)
    except ProcessLookupError:
        pass
    p.wait()
    finished = {m: m.read_bytes() for m in (out / "shards").glob("*/r0.json")}
    assert finished, "no shard had finished before the kill"
    work = out / ".work" / "csg_bitten" / "r0.csv"
    kept = work.read_text()
    assert not kept.endswith("\n"), "the killed shard's work CSV should end in a torn row"
    kept_rows = list(csv.DictReader(kept.splitlines()[:3]))
    assert not (out / "compare.csv").exists()

    run_workflow(out, wrapper, [str(REPO / i) for i in inputs], unlock=True)

    # finished shards were not repeated: their manifests are byte for byte the same
    for m, before in finished.items():
        assert m.read_bytes() == before, f"{m} was rerun"
    victim_manifest = json.loads((out / "shards" / "csg_bitten" / "r0.json").read_text())
    assert victim_manifest["mode"] == "--resume"
    rows = read_rows(out / "compare.csv")
    lines = (out / "compare.csv").read_text().splitlines()
    width = len(lines[0].split(","))
    assert all(len(next(csv.reader([ln]))) == width for ln in lines), "a torn line in compare.csv"
    keys = [(r["input"], r["replicate"], r["repr"], r["method"], r["resolution"], r["tolerance_px"],
             r["relaxation"]) for r in rows]
    assert len(keys) == len(set(keys)), "a run appears twice"
    assert {r["input"] for r in rows} == {"smooth_spheres", "csg_bitten", "smooth_capsules"}
    victim_rows = [r for r in rows if r["input"] == "csg_bitten"]
    full = read_rows(Path(str(marker) + ".full"))
    assert sorted(k[2:] for k in keys if k[0] == "csg_bitten") == sorted(
        (r["repr"], r["method"], r["resolution"], r["tolerance_px"], r["relaxation"]) for r in full)
    # the two whole rows written before the kill were kept, not measured again
    for k in kept_rows:
        assert any(v["timestamp"] == k["timestamp"] and v["method"] == k["method"] for v in victim_rows)
