"""CoACD verdict time: how soon ``peghole task make`` refuses or accepts a part that needs
CoACD, counted from the command's start, its imports included (issue 54, item 2).

    python -m benchmarks.studies.coacd_verdict \
        --out benchmarks/results/studies/coacd_verdict_cpu-2core.json

The pair: a 10 x 10 x 25 mm square peg in a blind square hole 0.25 mm larger all round whose
mouth is chamfered 2 mm, in a 30 x 30 x 20 mm block (not an extrusion, not a revolution:
CoACD), as exported coarse (12 / 36 faces) and as a fine export (each face split in four
until the peg has at least 3,000 and the hole 9,000 faces). Each case runs the ``peghole``
program in a process of its own (``python -m peghole_mjx.cli.main task make ...``) and reads its
standard error as it comes: the verdict is the first line that refuses (``error:``) or the
first line of the full run's bar (``parts searched / estimated``), timed from the process's
start. A case that runs on past its verdict is stopped at ``--max-s``. Resumable: each
finished case is saved under ``<out stem>_cases/``. Writes the JSON (rows and provenance)
and a CSV beside it.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import manifold3d
import numpy as np
import trimesh

from benchmarks.common import write_rows
from peghole_mjx.core import progress as prog
from peghole_mjx.core.validation import dumps, loads
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import run_provenance

COLUMNS = (
    "case",
    "peg_faces",
    "hole_faces",
    "args",
    "verdict",
    "verdict_s",
    "exit",
    "wall_s",
    "last_line",
)
#: the bar line of the full CoACD run (:func:`peghole_mjx.geometry.coacd_budget.run_bounded`)
BAR = "parts searched / estimated"
#: case -> (fine export, extra ``task make`` arguments)
CASES: dict[str, tuple[bool, list[str]]] = {
    "coarse, --max-hulls 4": (False, ["--max-hulls", "4"]),
    "fine, --max-hulls 4": (True, ["--max-hulls", "4"]),
    "fine, default caps": (True, []),
}


def _tm(m) -> trimesh.Trimesh:
    mesh = m.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def chamfered_pair(fine: bool, c: float = 0.25, chamfer: float = 2.0):
    """The module docstring's pair (mm): coarse, or split until 3,000 / 9,000 faces."""
    sq = manifold3d.CrossSection.square
    peg = manifold3d.Manifold.extrude(sq((10.0, 10.0), center=True), 25.0).translate((0, 0, -15))
    block = manifold3d.Manifold.cube((30, 30, 20), center=True).translate((0, 0, -10))
    w = 10 + 2 * c
    cavity = manifold3d.Manifold.extrude(sq((w, w), center=True), 16.0).translate((0, 0, -15))
    k = (w + 2 * chamfer) / w
    mouth = manifold3d.Manifold.extrude(
        sq((w, w), center=True), chamfer + 1e-3, scale_top=(k, k)
    ).translate((0, 0, -chamfer))
    peg, hole = _tm(peg), _tm(block - cavity - mouth)
    while fine and len(peg.faces) < 3000:
        peg = peg.subdivide()
    while fine and len(hole.faces) < 9000:
        hole = hole.subdivide()
    return peg, hole


def run_case(name: str, tmp: Path, max_s: float) -> dict:
    """One case: the command in its own process, its verdict timed from its start."""
    fine, extra = CASES[name]
    peg, hole = chamfered_pair(fine)
    folder = tmp / name.replace(" ", "_").replace(",", "")
    folder.mkdir(parents=True)
    peg.export(folder / "peg.stl")
    hole.export(folder / "hole.stl")
    argv = [sys.executable, "-m", "peghole_mjx.cli.main", "task", "make"]
    argv += [str(folder / "peg.stl"), str(folder / "hole.stl"), "--out", str(folder / "task")]
    t0 = time.perf_counter()
    proc = subprocess.Popen([*argv, *extra], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    verdict, verdict_s, line, last = "", None, b"", ""
    assert proc.stderr is not None
    while True:
        c = proc.stderr.read(1)
        if not c:
            break
        if c not in b"\r\n":
            line += c
            continue
        text = line.decode(errors="replace").strip()
        line = b""
        last = text or last
        if not verdict and ("error:" in text or BAR in text):
            verdict = "refused" if "error:" in text else "accepted (full run began)"
            verdict_s = round(time.perf_counter() - t0, 1)
        if time.perf_counter() - t0 > max_s:
            proc.terminate()
            last = f"stopped by the study at {max_s:g} s"
            break
    code = proc.wait()
    return {
        "case": name,
        "peg_faces": len(peg.faces),
        "hole_faces": len(hole.faces),
        "args": " ".join(extra),
        "verdict": verdict,
        "verdict_s": verdict_s,
        "exit": code,
        "wall_s": round(time.perf_counter() - t0, 1),
        "last_line": last[:400],
    }


def main(argv: list[str] | None = None) -> int:
    """Run the cases (resumable) and write the JSON and CSV."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--max-s", type=float, default=300.0, help="stop a case after this long")
    args = ap.parse_args(argv)
    command = ["python", "-m", "benchmarks.studies.coacd_verdict", *(argv or sys.argv[1:])]
    cases_dir = args.out.with_name(args.out.stem + "_cases")
    cases_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    bar = prog.bar(len(CASES), "CoACD verdicts", unit="case")
    with tempfile.TemporaryDirectory() as tmp:
        for name in CASES:
            saved = cases_dir / (name.replace(" ", "_").replace(",", "") + ".json")
            if saved.exists():
                rows.append(loads(saved.read_text()))
            else:
                bar.set_postfix_str(name)
                row = run_case(name, Path(tmp), args.max_s)
                fileio.write_text(saved, dumps(row, indent=2) + "\n")
                rows.append(row)
            bar.update()
    bar.close()
    doc = {
        "what": "issue 54 item 2: seconds from the start of `peghole task make` (its imports "
        "included) to the verdict on a part that needs CoACD",
        **run_provenance(command),
        "config": {
            "cases": {k: {"fine": v[0], "args": v[1]} for k, v in CASES.items()},
            "pair": "10 x 10 x 25 mm square peg, blind square hole 0.25 mm larger all round, "
            "mouth chamfered 2 mm, 30 x 30 x 20 mm block (mm STLs)",
            "max_s": args.max_s,
            "resumed_cases_from": str(cases_dir),
        },
        "columns": list(COLUMNS),
        "rows": rows,
    }
    fileio.write_text(args.out, dumps(doc, indent=2) + "\n")
    write_rows(args.out.with_suffix(".csv"), rows, COLUMNS)
    for r in rows:
        print({k: r[k] for k in COLUMNS if k != "last_line"}, r["last_line"][:200])
    return 0


if __name__ == "__main__":
    sys.exit(main())
