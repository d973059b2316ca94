"""Capture the command-line contracts on the bundled scene, to compare a refactoring's
before and after.

    python tools/capture_contracts.py capture DIR     # every command's --json and files
    python tools/capture_contracts.py compare OLD NEW  # what changed, timing fields aside

Each command runs in a fresh process with small sampler settings and fixed seeds, writing
under one fixed scratch folder (so that paths in the outputs agree between captures); its
``--json`` output, exit code and the JSON/CSV/.BSDF files it wrote are kept, and the
posterior draws of every ``posterior.nc`` as a JSON of arrays. Timing fields (``seconds``,
``wall``, …) and the scratch folder's name are left out of the comparison.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

SCRATCH = Path(os.environ.get("CONTRACTS_SCRATCH", "/tmp/brdf_infer_contracts"))
SMALL = ["--chains", "2", "--draws", "150", "--warmup", "150"]
SBC_SMALL = ["--replicates", "8", "--draws", "40", "--warmup", "100"]
SCENE = "data/lya.scene.toml"
COMMANDS: dict[str, list[str]] = {
    "run": ["run", "--out", "{o}/run", *SMALL, "--json"],
    "run-abg": ["run", "--out", "{o}/run-abg", "--model", "abg", *SMALL, "--json"],
    "fit-paper": ["fit", "--json"],
    "fit-lsq": ["fit", "--method", "lsq", "--json"],
    "fit-abg": ["fit", "--method", "lsq", "--model", "abg", "--json"],
    "fit-hs": ["fit", "--method", "lsq", "--model", "harvey-shack", "--json"],
    "posterior": ["posterior", "--out", "{o}/post", *SMALL, "--json"],
    "posterior-lambertian+abg": [
        "posterior",
        "--out",
        "{o}/post-labg",
        "--model",
        "lambertian+abg",
        *SMALL,
        "--json",
    ],
    "posterior-emcee": [
        "posterior",
        "--out",
        "{o}/post-emcee",
        "--sampler",
        "emcee",
        "--steps",
        "600",
        "--warmup",
        "200",
        "--json",
    ],
    "tis-params": ["tis", "--json"],
    "tis-run": ["tis", "--run", "{o}/post", "--json"],
    "tis-run-labg": ["tis", "--run", "{o}/post-labg", "--json"],
    "export-params": ["export", "--params", "uv-paper", "--out", "{o}/exp-params", "--json"],
    "export-run": ["export", "--run", "{o}/post", "--out", "{o}/exp-run", "--json"],
    "export-run-abg": [
        "export",
        "--run",
        "{o}/post",
        "--format",
        "abg",
        "--out",
        "{o}/exp-abg",
        "--json",
    ],
    "export-run-labg": ["export", "--run", "{o}/post-labg", "--out", "{o}/exp-labg", "--json"],
    "predict": ["predict", "--json"],
    "predict-aperture": ["predict", "--instrument", "aperture", "--json"],
    "compare": [
        "compare",
        "--models",
        "strumik2024",
        "abg",
        "lambertian",
        *SMALL,
        "--no-refit",
        "--out",
        "{o}/compare",
        "--json",
    ],
    "batch": [
        "batch",
        SCENE,
        "data/vis-532.scene.toml",
        *SMALL,
        "--out",
        "{o}/batch",
        "--json",
    ],
    "sbc": ["sbc", *SBC_SMALL, "--out", "{o}/sbc", "--json"],
    "sbc-abg": ["sbc", "--model", "abg", *SBC_SMALL, "--out", "{o}/sbc-abg", "--json"],
    "report": ["report", "{o}/post-labg", "--json"],
}
POSITIONAL_SCENE = {"run", "fit", "posterior", "predict", "compare", "sbc"}
TIMING = ("second", "wall", "elapsed", "time", "started", "finished", "date", "cache")
_STAMP = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?(?:[+-]\d\d:\d\d|Z)?")
KEPT_SUFFIXES = (".json", ".csv", ".bsdf", ".BSDF", ".txt", ".toml")


def _command(name: str, scratch: Path) -> list[str]:
    argv = [part.replace("{o}", str(scratch)) for part in COMMANDS[name]]
    if argv[0] in POSITIONAL_SCENE:
        argv.append(SCENE)
    return [sys.executable, "-m", "brdf_infer", *argv]


def _neutral(text: str) -> str:
    """``text`` with the scratch folder and the checkout's path replaced by placeholders."""
    return text.replace(str(SCRATCH), "<out>").replace(str(Path.cwd()), "<repo>")


def _draws(path: Path) -> dict:
    from brdf_infer._internal import arviz as az

    posterior = az.from_netcdf(path).posterior
    return {
        name: [float(v) for v in posterior[name].values.reshape(-1)]
        for name in sorted(posterior.data_vars)
    } | {
        "attrs": {
            k: _neutral(str(v)) for k, v in sorted(posterior.attrs.items()) if k != "created_at"
        }
    }


def capture(target: Path) -> None:
    shutil.rmtree(SCRATCH, ignore_errors=True)
    SCRATCH.mkdir(parents=True)
    target.mkdir(parents=True, exist_ok=True)
    for name in COMMANDS:
        done = subprocess.run(_command(name, SCRATCH), capture_output=True, text=True)
        print(f"{name}: exit {done.returncode}", flush=True)
        record = {"exit": done.returncode, "stderr_tail": done.stderr[-2000:]}
        try:
            record["json"] = json.loads(_neutral(done.stdout))
        except json.JSONDecodeError:
            record["stdout"] = done.stdout
        (target / f"{name}.json").write_text(json.dumps(record, indent=1, sort_keys=True))
    files = {}
    for path in sorted(SCRATCH.rglob("*")):
        key = str(path.relative_to(SCRATCH))
        if path.name == "posterior.nc":
            files[key] = _draws(path)
        elif path.suffix in KEPT_SUFFIXES:
            text = _neutral(path.read_text(errors="replace"))
            files[key] = json.loads(text) if path.suffix == ".json" else text
        elif path.is_file():
            files[key] = "present"
    (target / "files.json").write_text(json.dumps(files, indent=1, sort_keys=True))


def _timing(key: str) -> bool:
    return any(word in key.lower() for word in TIMING)


def _diff(old, new, where: str, out: list[str]) -> None:
    if isinstance(old, dict) and isinstance(new, dict):
        for key in sorted(set(old) | set(new)):
            if _timing(str(key)):
                continue
            if key not in old or key not in new:
                out.append(f"{where}/{key}: only in {'new' if key in new else 'old'}")
            else:
                _diff(old[key], new[key], f"{where}/{key}", out)
    elif isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        for k, (a, b) in enumerate(zip(old, new, strict=True)):
            _diff(a, b, f"{where}[{k}]", out)
    elif isinstance(old, float) and isinstance(new, float):
        if not (old == new or (math.isnan(old) and math.isnan(new))):
            scale = max(abs(old), abs(new), 1e-300)
            out.append(f"{where}: {old!r} → {new!r} (relative {abs(old - new) / scale:.1e})")
    elif isinstance(old, str) and isinstance(new, str):
        if _STAMP.sub("<time>", old) != _STAMP.sub("<time>", new):
            out.append(f"{where}: {old[:120]!r} → {new[:120]!r}")
    elif old != new:
        text = f"{where}: {str(old)[:120]!r} → {str(new)[:120]!r}"
        if not _timing(text):
            out.append(text)


def compare(old: Path, new: Path) -> int:
    changes: list[str] = []
    for path in sorted(old.glob("*.json")):
        other = new / path.name
        if not other.exists():
            changes.append(f"{path.name}: missing in {new}")
            continue
        a, b = json.loads(path.read_text()), json.loads(other.read_text())
        a.pop("stderr_tail", None), b.pop("stderr_tail", None)
        _diff(a, b, path.stem, changes)
    print("\n".join(changes) if changes else "no change")
    return 1 if changes else 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["capture"]:
        capture(Path(sys.argv[2]))
    elif sys.argv[1:2] == ["compare"]:
        sys.exit(compare(Path(sys.argv[2]), Path(sys.argv[3])))
    else:
        sys.exit(__doc__)
