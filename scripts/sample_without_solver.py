"""Profile: where a run spends the seconds with no linear solver under way, line by line.

Question: ``timing_without_solver`` in a run's ``summary.json`` splits the wall time during
which no linear solver runs on either thread by phase (assembly, refine, band, …). Which lines
of the package are those seconds spent in? They are what the solvers' share of the wall leaves
(the paper example's issue asks for at least 70 %), and a profiler of the whole run cannot tell
them apart: the background factorisations hide part of the main thread's work, not all of it.

Method: a sampling thread wakes every ``--interval`` seconds (default 2 ms) and charges the
seconds since its last wake during which no linear solver was under way (from the solver clock
:data:`ngat.timing.linear_solver`, so that the samples add up to the run's seconds without a
solver exactly) to the main thread's stack at the wake: its innermost line in the package, its
chain of up to four package frames, and the run's phase under way (:attr:`PhaseTimer.phase`
of the run's timer, found on the stack).
Time inside a library (NumPy, SciPy, Netgen) is charged to the package line that called it.
A sample sees the main thread only when the interpreter lets the sampling thread run, so the
lines of long calls that hold the interpreter are charged the waits before them too: the split
is an estimate, its total is exact. The run is ``ngat.driver.run`` of the scene (as
``bench_paper.py`` runs it, without the pictures).

Run ``python scripts/sample_without_solver.py`` (the paper's example, about 30 s) or
``--quick``; ``--until T`` stops the load history at t = T. Output in ``--out`` (default
``results/sample_without_solver``): ``samples.md`` (also printed: the top lines, the top
chains, and the seconds per phase sampled next to the run's ``timing_without_solver``),
``samples.json`` and ``samples.png`` (the top lines as bars, coloured by phase).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from ngat.driver import run  # noqa: E402
from ngat.scene import load_scene  # noqa: E402
from ngat.timing import WITHOUT_SOLVER_KEY, PhaseTimer, linear_solver  # noqa: E402

PACKAGE = "/ngat/"
"""Path fragment of the package's source files: their frames are the ones reported."""
CHAIN = 4
"""Package frames per chain, innermost first."""


def package_frames(frame, depth: int = CHAIN) -> list[str]:
    """Return ``file:function:line`` of the package's frames on a stack, innermost first."""
    chain = []
    while frame is not None and len(chain) < depth:
        code = frame.f_code
        if PACKAGE in code.co_filename:
            chain.append(f"{Path(code.co_filename).name}:{code.co_name}:{frame.f_lineno}")
        frame = frame.f_back
    return chain


def phase_timer(frame) -> PhaseTimer | None:
    """Return the :class:`PhaseTimer` a package frame on a stack holds (the run's), if any."""
    while frame is not None:
        if PACKAGE in frame.f_code.co_filename:
            timers = [v for v in frame.f_locals.values() if isinstance(v, PhaseTimer)]
            if timers:
                return timers[0]
        frame = frame.f_back
    return None


class Sampler:
    """Charge the seconds with no linear solver under way to the main thread's stack.

    Parameters
    ----------
    interval
        Seconds between wakes.
    clock
        The solver clock (:data:`ngat.timing.linear_solver`).
    """

    def __init__(self, interval: float, clock=linear_solver) -> None:
        self.interval = interval
        self.clock = clock
        self.target = threading.get_ident()
        self.timer: PhaseTimer | None = None  # the run's, found on the main thread's stack
        self.lines: Counter[str] = Counter()
        self.chains: Counter[str] = Counter()
        self.phases: Counter[str] = Counter()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def __enter__(self) -> Sampler:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._done.set()
        self._thread.join()

    def _where(self) -> tuple[list[str], str] | None:
        """Return the main thread's package frames and phase now (``None``: no main thread)."""
        frame = sys._current_frames().get(self.target)
        if frame is None:
            return None
        chain = package_frames(frame) or ["outside the package"]
        self.timer = self.timer or phase_timer(frame)
        phase = self.timer.phase if self.timer is not None else "before the run's timer"
        return chain, phase

    def _sample(self) -> None:
        """Charge each interval's seconds with no solver under way, until the run ends.

        A solver under way at the wake began inside the interval, after its seconds with
        none: those are charged to the last stack seen with no solver under way, not to the
        solver's, and the stack is not read (a solve runs most of the time: the sampler's own
        work stays small).
        """
        now, busy, where = self.clock.now(), self.clock.seconds(), self._where()
        while not self._done.wait(self.interval):
            then, busy_then = now, busy
            now, busy = self.clock.now(), self.clock.seconds()
            idle = (now - then) - (busy - busy_then)
            if not self.clock.busy:
                where = self._where()
            if idle <= 0 or where is None:
                continue
            chain, phase = where
            self.lines[chain[0]] += idle
            self.chains[" < ".join(chain)] += idle
            self.phases[phase] += idle


def sample(quick: bool, until: float | None, interval: float, folder: Path) -> dict:
    """Run two-slits (or its quick variant) under a :class:`Sampler`; return both accounts."""
    scene = load_scene("two-slits")
    parameters, times = scene.configure(quick=quick)
    if until is not None:
        times = times[times <= until + 1e-12]
    with Sampler(interval) as sampler:
        result = run(scene, parameters, times, folder)
    timing = result.summary["timing"]
    return {
        "wall_s": timing["wall"],
        "sampled_s": round(sum(sampler.lines.values()), 3),
        "without_solver_s": result.summary[WITHOUT_SOLVER_KEY],
        "phases_s": {k: round(v, 3) for k, v in sampler.phases.most_common()},
        "lines_s": {k: round(v, 3) for k, v in sampler.lines.most_common()},
        "chains_s": {k: round(v, 3) for k, v in sampler.chains.most_common()},
    }


def report(samples: dict, top: int) -> str:
    """Return the Markdown tables of ``samples.md``."""
    phases = sorted(
        set(samples["phases_s"]) | set(samples["without_solver_s"]),
        key=lambda p: -samples["without_solver_s"].get(p, 0.0),
    )
    out = [
        f"Run {samples['wall_s']:.2f} s; with no linear solver under way "
        f"{sum(samples['without_solver_s'].values()):.2f} s by the run's phase timer, "
        f"{samples['sampled_s']:.2f} s sampled.",
        "",
        "| phase | run's timer [s] | sampled [s] |",
        "|---|---:|---:|",
        *(
            f"| {p} | {samples['without_solver_s'].get(p, 0.0):.2f} | "
            f"{samples['phases_s'].get(p, 0.0):.2f} |"
            for p in phases
        ),
        "",
        f"| innermost line of the package (top {top}) | sampled [s] |",
        "|---|---:|",
        *(f"| `{k}` | {v:.2f} |" for k, v in list(samples["lines_s"].items())[:top]),
        "",
        f"| chain, innermost first (top {top}) | sampled [s] |",
        "|---|---:|",
        *(f"| `{k}` | {v:.2f} |" for k, v in list(samples["chains_s"].items())[:top]),
    ]
    return "\n".join(out) + "\n"


def plot(samples: dict, top: int, path: Path) -> None:
    """Draw the top lines as horizontal bars."""
    lines = list(samples["lines_s"].items())[:top][::-1]
    fig, ax = plt.subplots(figsize=(9, 0.28 * len(lines) + 1.2), layout="constrained")
    ax.barh([k for k, _ in lines], [v for _, v in lines], color="tab:blue")
    ax.set_xlabel("seconds with no linear solver under way")
    ax.set_title(
        f"{samples['sampled_s']:.1f} s sampled of a {samples['wall_s']:.1f} s run", fontsize=10
    )
    ax.tick_params(axis="y", labelsize=7)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="the scene's quick variant")
    parser.add_argument("--until", type=float, help="stop the load history at this time")
    parser.add_argument("--interval", type=float, default=0.002, help="seconds between samples")
    parser.add_argument("--top", type=int, default=25, help="lines and chains in the tables")
    parser.add_argument("--out", default="results/sample_without_solver", help="output folder")
    args = parser.parse_args()
    if args.interval <= 0:
        parser.error("--interval must be positive")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    samples = sample(args.quick, args.until, args.interval, out / "run")
    (out / "samples.json").write_text(json.dumps(samples, indent=1))
    text = report(samples, args.top)
    (out / "samples.md").write_text(text)
    plot(samples, args.top, out / "samples.png")
    print(text, end="")


if __name__ == "__main__":
    main()
