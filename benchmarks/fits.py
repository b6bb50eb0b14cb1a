"""Benchmark: the simultaneous ODE fit of Eqn 27 over 20 chambers x 100 points (issue 3 target).

Run with ``python benchmarks/fits.py [--repeat 5] [--seed 0]``.

Data: the four PDMS chambers of the paper (reference, small radius, thick
membrane, low concentration), five of each, simulated with the Table 3 law
(``DoubleExponential.PDMS``) at 100 times over 24 h, with 1 % multiplicative
noise.  Cases, each timed ``--repeat`` times (median, min, max):

* ``fit_permeability(model="double_exponential")``: Eqn 27 through the ODE, all
  chambers at once (the issue's target: < 5 s on one core);
* ``fit_permeability(model="constant")`` (hyperelastic, constant P_w) for scale;
* ``analyze_instantaneous(direct=False)``: the paper's route (Eqn 25 rates and
  Eqn 27 fitted to them).

ODE solves are counted by wrapping ``VolumePath.solve`` (one quadrature of
Eqn 8 for one chamber and one trial law) and compared with the fit's own
``n_ode_solves``; ``nfev`` is lmfit's count of residual evaluations (each solves
all 20 chambers).  The mechanics table comes from the disk cache (built once,
untimed, before the runs).

The process is pinned to one core: BLAS/OpenMP threads are set to 1 before
numpy is imported and the affinity is restricted to one CPU where the OS allows.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
             "VECLIB_MAXIMUM_THREADS", "BLIS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import osmobulge.modeling.simulate as simulate_mod  # noqa: E402
from osmobulge.modeling.fitting import fit_permeability  # noqa: E402
from osmobulge.modeling.instantaneous import analyze_instantaneous  # noqa: E402
from osmobulge.modeling.materials import PDMS  # noqa: E402
from osmobulge.modeling.permeability import DoubleExponential  # noqa: E402
from osmobulge.modeling.simulate import simulate  # noqa: E402
from osmobulge.modeling.transport import mechanics_model, paper_chamber  # noqa: E402

CONDITIONS = ("reference", "small_radius", "thick_membrane", "low_concentration")
N_PER_CONDITION = 5
N_POINTS = 100
TARGET_S = 5.0


def pin_to_one_core() -> str:
    """Restrict the process to one CPU of its affinity set; describe what was done."""
    if not hasattr(os, "sched_setaffinity"):
        return "affinity not supported (threads limited to 1)"
    cpus = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpus[-1]})
    return f"pinned to CPU {cpus[-1]} of {cpus}"


class SolveCounter:
    """Count calls of ``VolumePath.solve`` (one Eqn 8 quadrature per chamber and trial law)."""

    def __init__(self):
        self.calls = 0
        self._orig = simulate_mod.VolumePath.solve

    def __enter__(self):
        orig = self._orig

        def counted(path_self, pw):
            self.calls += 1
            return orig(path_self, pw)

        simulate_mod.VolumePath.solve = counted
        return self

    def __exit__(self, *exc):
        simulate_mod.VolumePath.solve = self._orig
        return False


def make_observations(seed: int):
    """20 noisy chambers x 100 points simulated with the Table 3 PDMS law."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 24 * 3600.0, N_POINTS)
    obs = []
    for name in CONDITIONS:
        chamber = paper_chamber(name)
        v = simulate(chamber, PDMS, DoubleExponential.PDMS, t)["volume_ratio"].values
        for _ in range(N_PER_CONDITION):
            e = 1.0 + 0.01 * rng.standard_normal(t.size)
            e[0] = 1.0
            obs.append((chamber, t, v * e))
    return obs


def run_case(fn, repeat: int):
    """Wall times of ``repeat`` runs and the solve count / result of the last one."""
    times, counts, result = [], [], None
    for _ in range(repeat):
        with SolveCounter() as counter:
            t0 = time.perf_counter()
            result = fn()
            times.append(time.perf_counter() - t0)
        counts.append(counter.calls)
    return times, counts, result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per case (median reported)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the synthetic noise")
    args = parser.parse_args(argv)

    pinning = pin_to_one_core()
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    mechanics_model(PDMS)  # build / load the cached mechanics table, untimed
    obs = make_observations(args.seed)
    truth = float(DoubleExponential.PDMS(1.0))
    cases = [
        ("fit_permeability double_exponential (Eqn 27 via ODE)",
         lambda: fit_permeability(obs, PDMS, model="double_exponential"), TARGET_S),
        ("fit_permeability constant (hyperelastic)", lambda: fit_permeability(obs, PDMS, model="constant"), None),
        ("analyze_instantaneous spline, Eqn 27 on rates",
         lambda: analyze_instantaneous([(c, t, v, str(i)) for i, (c, t, v) in enumerate(obs)], PDMS,
                                       direct=False), None),
    ]
    rows = []
    for name, fn, target in cases:
        times, counts, res = run_case(fn, args.repeat)
        if hasattr(res, "p_at_rest"):
            p1, nfev, own = float(res.p_at_rest), int(res.nfev), int(res.n_ode_solves)
            if "constant" in name:
                p1 = float(res.params["p"])
        else:
            p1, nfev, own = float(res.eqn27.params["p_at_rest"]), 0, 0
        rows.append((name, statistics.median(times), min(times), max(times), target, counts[-1], own, nfev, p1))
    load_after = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")

    print(f"osmobulge fits benchmark: {platform.python_implementation()} {platform.python_version()}, "
          f"numpy {np.__version__}, {platform.machine()}; {pinning}; BLAS/OMP threads = 1")
    print(f"data: {len(obs)} chambers x {N_POINTS} points (4 PDMS conditions x {N_PER_CONDITION}), Table-3 law, "
          f"1 % noise, seed {args.seed}; median of {args.repeat} runs; "
          f"1-min load average before/after {load_before:.2f}/{load_after:.2f} (2 cores shared)")
    header = (f"{'case':<52} {'median':>9} {'min':>9} {'max':>9} {'target':>7} {'ratio':>6} "
              f"{'solves':>7} {'(own)':>7} {'nfev':>5} {'P_w(1) or P_w':>13}")
    print(header)
    print("-" * len(header))
    for name, med, lo, hi, target, solves, own, nfev, p1 in rows:
        tgt = f"{target:.1f} s" if target else "-"
        ratio = f"{med / target:.2f}" if target else "-"
        print(f"{name:<52} {med:>7.3f} s {lo:>7.3f} s {hi:>7.3f} s {tgt:>7} {ratio:>6} {solves:>7d} {own:>7d} "
              f"{nfev:>5d} {p1:>13.4e}")
    print(f"truth P_w(1) = {truth:.4e} m^2/s; solves = calls of VolumePath.solve (one chamber, one trial law) "
          "counted by wrapping it, (own) = the fit's n_ode_solves; ratio = median/target (< 1 meets it)")


if __name__ == "__main__":
    main()
