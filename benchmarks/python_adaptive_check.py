"""Would python-adaptive plan an adaptive campaign deterministically? (the evidence behind
docs/campaigns/refinement.md, "Why not python-adaptive").

Feeds the library the same data in different orders and prints what it asks for next, on a
step like the Fig. A1 boundary at chi (alpha - B) = 8 (eps_c = 0.1396):

- ``Learner1D`` with a smallest interval (``resolution_loss_function``): how many of 50
  orders of the same eight told points give another ``ask(3)``;
- ``AverageLearner1D`` (seeds as its integer sample ids): which (seed, x) it asks for after
  seeds 0, 1 (and after seeds 3, 7) at five points, told in two orders.

Needs the library, which the project does not depend on: ``pip install adaptive``.

    python benchmarks/python_adaptive_check.py
"""

from __future__ import annotations

import math
import random
import sys


def main() -> int:
    try:
        import adaptive
        from adaptive import AverageLearner1D, Learner1D
        from adaptive.learner.learner1D import resolution_loss_function
    except ImportError:
        print("error: this check needs python-adaptive (pip install adaptive)", file=sys.stderr)
        return 2
    print(f"adaptive {adaptive.__version__}")

    def g(x: float) -> float:  # a smooth step at the boundary
        return math.tanh((x - 0.1396) / 0.01) + 0.1 * x

    told = [0.0, 0.1, 0.2, 0.3, 0.4, 0.15, 0.125, 0.05]
    answers: dict[tuple[float, ...], int] = {}
    for k in range(50):
        order = told[:]
        random.Random(k).shuffle(order)
        learner = Learner1D(
            None, bounds=(0.0, 0.4), loss_per_interval=resolution_loss_function(min_length=0.0625)
        )
        for x in order:
            learner.tell(x, g(x))
        points, _ = learner.ask(3, tell_pending=False)
        key = tuple(points)
        answers[key] = answers.get(key, 0) + 1
    print("Learner1D.ask(3) over 50 orders of the same data:")
    for key, n in sorted(answers.items(), key=lambda kv: -kv[1]):
        print(f"  {n:2d} x {list(key)}")

    def step(x: float) -> float:
        return 1.0 if x > 0.1396 else 0.0

    xs = [0.0, 0.1, 0.2, 0.3, 0.4]
    for seeds, xorder in (((0, 1), xs), ((1, 0), xs[::-1]), ((3, 7), xs)):
        avg = AverageLearner1D(None, bounds=(0.0, 0.4))
        for x in xorder:
            for s in seeds:
                avg.tell((s, x), step(x))
        points, _ = avg.ask(6, tell_pending=False)
        print(f"AverageLearner1D told seeds {seeds} at x in {xorder}: asks {points}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
