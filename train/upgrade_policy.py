"""Rewrite policy folders in the current policy format (``peghole_mjx.policies.FORMAT_VERSION``).

    python train/upgrade_policy.py [DIR ...]      (default: the committed pretrained policies)

Format 1 (arrays stored by position, ``leaf_0000``...) becomes format 2 (arrays named by tree
path); the arrays are unchanged bit for bit and the rest of ``policy.json`` is kept. A folder
already current is left alone. ``peghole`` reads format 1 as well (upgraded on load), so this
only makes the files self-describing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from peghole_mjx.policies import FORMAT_VERSION, PRETRAINED, upgrade_policy


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dirs", nargs="*", type=Path, help="policy folders (policy.json, params.npz)")
    args = ap.parse_args(argv)
    for d in args.dirs or list(PRETRAINED.values()):
        changed = upgrade_policy(d)
        print(f"{d}: {'rewritten as' if changed else 'already'} format {FORMAT_VERSION}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
