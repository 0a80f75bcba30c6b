"""Training entry point, the same as ``peghole train`` (run from a checkout without installing
the console script): ``python train/train.py --env RectExtract --quick --out runs/q``.

Hyperparameters: ``train/configs/<ENV>.json``; documentation: ``docs/guide/training.md``.
"""

import sys

from peghole_mjx.cli.main import main

if __name__ == "__main__":
    sys.exit(main(["train", *sys.argv[1:]]))
