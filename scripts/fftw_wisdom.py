"""Regenerate the FFTW wisdom shipped with the model (``model/fftw_wisdom.txt``).

    .venv/bin/python scripts/fftw_wisdom.py            # the default sizes, ~1 min
    .venv/bin/python scripts/fftw_wisdom.py 64 128     # only these N x N

Plans every N x N real transform pair with FFTW_PATIENT (FFTW times candidate algorithms) and
writes FFTW's wisdom, atomically. Every later process imports it and plans from it without
timing anything, so all processes run the same algorithm and results stay bitwise
reproducible (model/compiled/fftw.py). Run it on a quiet machine: the timings choose the plans.
Sizes not in the file get FFTW_ESTIMATE plans (deterministic as well, slower at 128^2).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

from nematic_solids.model.compiled import fftw as fftw_native

SIZES = [16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512]


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("sizes", nargs="*", type=int, metavar="N", help="grid sizes N (N x N)")
    sizes = parser.parse_args(argv).sizes or SIZES
    if not fftw_native.AVAILABLE:
        print("the native FFTW library is not available: nothing to do", file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    wisdom = fftw_native.patient_wisdom(sizes)
    target = fftw_native.WISDOM_FILE
    if target is None:
        print("NEMATIC_FFTW_WISDOM is empty: no file to write", file=sys.stderr)
        return 1
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".wisdom-")
    with os.fdopen(fd, "w") as fh:
        fh.write(wisdom)
    os.replace(tmp, target)
    print(
        f"FFTW_PATIENT wisdom for N = {sizes} written to {target} "
        f"({len(wisdom)} bytes, {time.perf_counter() - t0:.1f} s)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
