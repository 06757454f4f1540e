"""Runs ``ergo`` commands on a file system that is full, then read-only, for real: a small
tmpfs mounted in a private user and mount namespace (``unshare --user --map-root-user
--mount``: no privilege on the machine, the mount invisible to other processes and gone with
this one). Used by ``test_full_or_read_only_disk.py``::

    unshare -rm python tests/system/disk_faults.py PLAN.json REPORT.json

PLAN: ``{"mount": DIR, "size_kb": N, "copy": {NAME: SOURCE}, "phases": [{"fill": true |
"readonly": true, "commands": [[ARG, ...], ...]}]}``: SOURCE folders and files are copied
into DIR/NAME, then each phase fills the file system (a filler file until ENOSPC) or remounts
it read-only, and runs its commands in this process (``explore.cli.main``, stderr captured at
the descriptor). REPORT: per command its exit code, its stderr, and a listing (path -> size,
sha256 of the files) of DIR after it.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path


def listing(root: Path) -> dict[str, str]:
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file() and not p.is_symlink() and p.name != "filler":
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()[:16]
        elif p.is_dir():
            out[str(p.relative_to(root)) + "/"] = ""
    return out


def run(args: list[str]) -> tuple[int | str, str]:
    from explore.cli import main

    with tempfile.TemporaryFile() as err:
        saved = os.dup(2)
        os.dup2(err.fileno(), 2)
        try:
            try:
                rc: int | str = main(args)
            except SystemExit as exc:
                rc = exc.code if isinstance(exc.code, int) else 1
            except BaseException:
                rc = "exception"
                traceback.print_exc()
            sys.stderr.flush()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        err.seek(0)
        return rc, err.read().decode(errors="replace")


def main(plan_path: str, report_path: str) -> int:
    plan = json.loads(Path(plan_path).read_text())
    mount = Path(plan["mount"])
    mount.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={plan['size_kb']}k", "tmpfs", str(mount)],
                   check=True)  # fmt: skip
    for name, source in plan["copy"].items():
        src = Path(source)
        (shutil.copytree if src.is_dir() else shutil.copy)(src, mount / name)
    initial = listing(mount)
    report = []
    for phase in plan["phases"]:
        if phase.get("fill"):
            fd = os.open(mount / "filler", os.O_WRONLY | os.O_CREAT)
            with contextlib.suppress(OSError):
                while True:
                    os.write(fd, b"\0" * 4096)
            os.close(fd)
        if phase.get("readonly"):
            subprocess.run(["mount", "-o", "remount,ro", str(mount)], check=True)
        for args in phase["commands"]:
            rc, err = run(args)
            report.append({"args": args, "rc": rc, "stderr": err, "after": listing(mount)})
    Path(report_path).write_text(json.dumps({"initial": initial, "commands": report}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
