"""The report's memory section (sdfmesh_tools.memory): declared bytes against the measured
heap peak, with a known answer planted in synthetic rows."""

from sdfmesh_tools import memory
from test_study import row


def rows_of(n_inputs=6):
    """Per input: the closed-form reference (the floor: 100 kB measured), an SDF run declaring
    1 kB and measuring the floor, and a mesh run declaring 100 kB and measuring 4x that (its
    build scratch). An implicit class's SDF run declares 5 MB and measures the floor (its
    prepared model uncounted)."""
    out = []
    for i in range(n_inputs):
        for cls in ("smooth", "implicit"):
            name = f"{cls}_{i}"
            ref = row(name, cls, 0, "analytic", "closed-form", total_bytes=1_000, quality=0.5)
            sdf = row(name, cls, 0, "sdf", "sphere-trace", tol="1.0", relax="1.0",
                      total_bytes=5_000_000 if cls == "implicit" else 1_000)
            mesh = row(name, cls, 0, "mesh", "extracted", res=32, total_bytes=100_000)
            for r, heap in ((ref, 100_000), (sdf, 100_000), (mesh, 400_000)):
                r["peak_heap_bytes"] = heap
                r["asked_repr"] = r["repr"]
                out.append(r)
    return out


def test_the_measured_verdict_the_floor_the_scratch_and_the_shared_data_are_found():
    rows = rows_of()
    v = {x["class"]: x for x in memory.verdicts(rows, 1.0)}
    # smooth: declared 1 kB / 100 kB; measured 100 kB / 400 kB.
    assert abs(v["smooth"]["declared"]["ratio"] - 0.01) < 1e-9
    assert abs(v["smooth"]["measured"]["ratio"] - 0.25) < 1e-9
    # implicit: declared 50x larger on the SDF side, measured 4x smaller.
    assert abs(v["implicit"]["declared"]["ratio"] - 50) < 1e-6
    assert memory.floor_bytes(rows) == 100_000
    assert memory.below_declared(rows) == {"implicit": {"sdf/sphere-trace"}}
    fams = {f[0]: f for f in memory.family_table(rows)}
    assert fams["mesh/extracted"][4] == 4.0
    text = memory.section(rows, 1.0)
    assert "median 100 kB (64×64)" in text
    # (400 kB - the 100 kB floor) / 100 kB declared; the SDF run measures the floor only.
    assert "`mesh/extracted` 3×" in text and "`sdf/sphere-trace` " not in text.split("build scratch")[1].split(".")[0]
    assert "implicit: `sdf/sphere-trace`" in text and "prepared cells" in text
    # With an appendix the per-representation table goes there and the section links it.
    short = memory.section(rows, 1.0, "appendix-memory.md")
    assert "[appendix-memory.md](appendix-memory.md)" in short and "`mesh/extracted` | " not in short
    assert "`mesh/extracted` | " in text and "`mesh/extracted` | " in memory.family_markdown(memory.family_table(rows))


def test_no_measured_heap_gives_no_section():
    rows = rows_of(2)
    for r in rows:
        r["peak_heap_bytes"] = ""
    assert memory.section(rows, 1.0) == ""
