"""Benchmark: particle-steps per second of a 3D dam break with about 60k particles.

Measures, at 1 and 2 threads:

* ``unmesh`` WCSPH, fluid only (density pass + force pass + sorting + integration), on the
  setup SPlisHSPlasH runs: a water column of 47 × 87 × 15 particles on a cubic grid of spacing
  d = 0.01 m (``SPHConfig(lattice="cubic")``, h = 2d: about 30 neighbours), in a 1.4 × 0.9 × 0.18 m
  tank, ρ0 = 1000 kg/m³, K = 50 000 Pa, Γ = 7, negative pressures clamped, Δt = 1e-4 s;
* ``unmesh`` WCSPH, fluid only, on the closest packing of the elastic case (the same particles,
  about 46 neighbours), to show what elasticity itself costs;
* ``unmesh`` with elasticity: a 0.35 × 0.7 × 0.18 m jelly block on the closest packing (lattice
  assignment, shape matching, goal positions, exact torque correction, gather);
* SPlisHSPlasH's WCSPH (``pip install pysplishsplash``) on the same setup (same grid, particle
  count, tank, ρ0, K, Γ and Δt; Akinci boundary particles), run in a subprocess with
  ``OMP_NUM_THREADS`` and ``LD_PRELOAD=libGLdispatch.so.0`` (its import needs it headless).

Prints one table and the ratios the issue asks for (elastic/fluid, unmesh/SPlisHSPlasH).
Timings are wall clock and CPU time of the stepping only (compilation and set-up excluded). The
three unmesh cases are built first and then stepped in turns of ``--turn`` timed steps (one
untimed step before each turn), in the order fluid, CCP, elastic, then elastic, CCP, fluid, and so
on: a load on the shared machine that changes during the run weighs on every case alike, so the
ratios compare the cases under the same conditions.

First the shipped 3D dam break (``examples/sph/dam_break.toml``, 17 600 particles) between t = 0.1 and
0.2 s with and without Verlet neighbour lists (``neighbor_skin`` 0.2 and 0), with the split of its step
(issue 22 item 4: >= 1.5 M particle-steps/s on 2 cores); ``--shipped-only`` stops there.

Then validates the shipped 3D dam break (``examples/sph/dam_break.toml``, a = 0.25 m,
spacing a/20, no-slip tank walls) against Martin & Moyce (1952), n² = 2: the surge front Z = x/a at the
experiment's times T = t·√(2g/a), with the relative error per point and the largest error
for T ≤ 3 (goal: 10 %). This part takes a few minutes; skip it with ``--no-validation``.

Usage::

    python benchmarks/bench_sph.py [--steps 60] [--spacing 0.01] [--no-splishsplash] [--no-validation]
                                   [--shipped-only]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

#: The user's GOMP_SPINCOUNT before ``import unmesh`` sets its default (SPlisHSPlasH runs with the user's).
USER_SPINCOUNT = os.environ.get("GOMP_SPINCOUNT")

# The elastic block: width x height x depth (m), and the tank (both cases).
COLUMN = (0.35, 0.7, 0.18)
TANK = (1.4, 0.9, 0.18)
#: Target particle count of the fluid column.
FLUID_PARTICLES = 61000
#: The fluid of both codes (SPlisHSPlasH's WCSPH parameters): rest density, stiffness, exponent, time step.
RHO0, STIFFNESS, EXPONENT, DT = 1000.0, 50000.0, 7.0, 1e-4


def fluid_block(spacing: float) -> tuple[int, int, int]:
    """Particles (nx, ny, nz) of the cubic-grid water column, about :data:`FLUID_PARTICLES` in all.

    The column fills the tank's depth less a spacing on each side and is twice as high as wide
    where the tank allows.
    """
    nz = int((TANK[2] - 2 * spacing) / spacing - 0.5)
    cells = FLUID_PARTICLES * (0.01 / spacing) ** 3 / nz
    ny = min(round(math.sqrt(2 * cells)), int((TANK[1] - 2 * spacing) / spacing - 0.5))
    return round(cells / ny), ny, nz


def build_case(spacing: float, case: str):
    """The unmesh simulation of a case: ``"fluid"`` (cubic grid, the SPlisHSPlasH setup), ``"fluid-ccp"``
    (the elastic block's closest packing as a fluid) or ``"elastic"``."""
    from unmesh.sph import Material, SPHConfig, SPHObject, SPHSimulation, box_planes
    from unmesh.sph.sampling import closest_packing, cubic_grid

    lattice = "closest"
    if case == "fluid":
        nx, ny, nz = fluid_block(spacing)
        x = cubic_grid([0, 0, 0], [nx * spacing, ny * spacing, nz * spacing], spacing, 3)
        lattice = "cubic"
    else:
        x = closest_packing([0, 0, 0], COLUMN, spacing, 3)
    if case == "elastic":
        mat = Material("jelly", stiffness=2000.0, elastic_stiffness=1e6, xsph=0.1)
        obj = SPHObject("jelly", x, "jelly", phase="solid")
    else:
        mat = Material("water", density=RHO0, stiffness=STIFFNESS, gamma=EXPONENT, negative_pressure=0.0)
        obj = SPHObject("water", x, "water")
    cfg = SPHConfig(dim=3, spacing=spacing, dt=DT, gravity=(0, -9.81, 0), lattice=lattice)
    return SPHSimulation(cfg, {mat.name: mat}, [obj], planes=box_planes([0, 0, 0], TANK, 3, open_top=True))


def unmesh_rates(spacing: float, steps: int, threads: int, cases: tuple[str, ...], turn: int = 10) -> dict[str, tuple]:
    """Per case: (particles, particle-steps per wall second, per CPU second, mean neighbours).

    After 3 warm-up steps each, the cases are stepped in turns of ``turn`` timed steps (one untimed
    step before each turn), in the order ``cases``, then reversed, and so on until each case has
    run ``steps`` timed steps.
    """
    import numba

    import unmesh  # noqa: F401  (before numba starts its threads: unmesh's GOMP_SPINCOUNT default)

    numba.set_num_threads(threads)
    sims = {case: build_case(spacing, case) for case in cases}
    for sim in sims.values():
        for _ in range(3):  # compile and warm up
            sim.step()
    timed = {case: [0.0, 0.0, 0] for case in cases}
    order = [case for k in range(-(-steps // turn)) for case in (cases if k % 2 == 0 else cases[::-1])]
    for case in order:
        sim = sims[case]
        sim.step()  # back in the caches after the other cases
        n = min(turn, steps - timed[case][2])
        t0 = time.perf_counter()
        c0 = time.process_time()
        for _ in range(n):
            sim.step()
        timed[case][0] += time.perf_counter() - t0
        timed[case][1] += time.process_time() - c0
        timed[case][2] += n
    out = {}
    for case, (wall, cpu, n) in timed.items():
        count = len(sims[case].x)
        out[case] = (count, count * n / wall, count * n / cpu, float(sims[case].nnbr.mean()))
    return out


#: Kernels of the step whose time :func:`shipped_dam_break` splits out (the rest is Python, sorting, integration).
SPLIT = ("density_pass", "density_list_pass", "force_pass")


def shipped_dam_break(threads: int, skins: tuple[float, ...] = (0.2, 0.0), t0: float = 0.1, t1: float = 0.2,
                      turn: int = 25) -> None:
    """Particle-steps/s of the shipped dam break (``examples/sph/dam_break.toml``) between ``t0`` and ``t1``.

    Issue 22 item 4 measures the shipped scene (17 600 particles, about 42 neighbours, no-slip walls) through
    ``unmesh sph`` (0.2 s run less 0.1 s run); here the same steps run in process, one simulation per
    ``neighbor_skin`` in ``skins`` (0: a cell scan and re-sort every step), advanced untimed to ``t0`` and then
    stepped to ``t1`` in alternating turns of ``turn`` steps. Prints wall and CPU time per step, particle-steps
    per wall second, the cell scans per step and the wall time split among the density scan, the density pass
    over the stored Verlet candidates, the force pass and the rest.
    """
    import numba

    import unmesh  # noqa: F401  (before numba starts its threads: unmesh's GOMP_SPINCOUNT default)
    from unmesh.scene import load_scene
    from unmesh.scenes import path as scene_path
    from unmesh.sph import _kernels as K
    from unmesh.sph.scene import build_simulation

    numba.set_num_threads(threads)
    split: dict[str, float] = {}
    originals = {name: getattr(K, name) for name in SPLIT}

    def timed(name):
        def call(*args):
            w = time.perf_counter()
            out = originals[name](*args)
            split[name] = split.get(name, 0.0) + time.perf_counter() - w
            return out
        return call

    sims = {}
    for skin in skins:
        sim, _ = build_simulation(load_scene(scene_path("sph/dam_break.toml"), {"simulation.neighbor_skin": skin}))
        while sim.time < t0:
            sim.step()
        sims[skin] = sim
    stats = {skin: {"wall": 0.0, "cpu": 0.0, "steps": 0, "scans": 0, **dict.fromkeys(SPLIT, 0.0)} for skin in skins}
    for name in SPLIT:
        setattr(K, name, timed(name))
    try:
        k = 0
        while any(sim.time < t1 for sim in sims.values()):
            for skin in (skins if k % 2 == 0 else skins[::-1]):
                sim, st = sims[skin], stats[skin]
                split.clear()
                s0 = sim.neighbor_scans
                w, c = time.perf_counter(), time.process_time()
                n = 0
                while n < turn and sim.time < t1:
                    sim.step()
                    n += 1
                st["wall"] += time.perf_counter() - w
                st["cpu"] += time.process_time() - c
                st["steps"] += n
                st["scans"] += sim.neighbor_scans - s0
                for name in SPLIT:
                    st[name] += split.get(name, 0.0)
            k += 1
    finally:
        for name in SPLIT:
            setattr(K, name, originals[name])
    print(f"\nShipped dam break (examples/sph/dam_break.toml), t = {t0}-{t1} s, {threads} thread(s), "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'neighbor_skin':>13s} {'particles':>9s} {'steps':>6s} {'ms/step':>8s} {'CPU ms/step':>11s} "
          f"{'M particle-steps/s':>19s} {'scans/step':>10s} {'scan':>6s} {'list':>6s} {'force':>6s} {'rest':>6s}")
    for skin, st in stats.items():
        n = st["steps"]
        ms = {name: st[name] / n * 1e3 for name in SPLIT}
        rest = st["wall"] / n * 1e3 - sum(ms.values())
        count = len(sims[skin].x)
        print(f"{skin:13g} {count:9d} {n:6d} {st['wall'] / n * 1e3:8.2f} {st['cpu'] / n * 1e3:11.2f} "
              f"{count * n / st['wall'] / 1e6:19.3f} {st['scans'] / n:10.3f} {ms['density_pass']:6.2f} "
              f"{ms['density_list_pass']:6.2f} {ms['force_pass']:6.2f} {rest:6.2f}")
    print("goal: >= 1.5 M particle-steps/s on 2 quiet cores (#22.4); scan/list/force/rest: wall ms per step")


#: Martin & Moyce (1952), n² = 2, a = 2.25 in: surge front Z = x/a at T = t·√(2g/a) (issue 4).
MARTIN_MOYCE_T = (0.832, 1.219, 1.997, 2.547, 3.345)
MARTIN_MOYCE_Z = (1.217, 1.474, 2.292, 2.995, 4.134)


def dam_break_validation(resolution: int = 20) -> None:
    """Run the shipped dam break at spacing a/resolution and print the surge-front error."""
    import numpy as np

    from unmesh.scene import load_scene
    from unmesh.scenes import path as scene_path
    from unmesh.sph.front import surge_front
    from unmesh.sph.scene import build_simulation

    a, g = 0.25, 9.81
    spacing = a / resolution
    sim, _ = build_simulation(load_scene(scene_path("sph/dam_break.toml"), {"simulation.spacing": spacing}))
    t0 = time.perf_counter()
    walls = "no-slip" if all(p.no_slip for p in sim.planes) else "free-slip"
    print(f"\nDam break vs Martin & Moyce (1952): 3D, a = {a} m, spacing a/{resolution}, {len(sim.x)} particles, "
          f"{walls} walls, instant release; front = largest x of a particle with a neighbour within 1.5 d")
    errors = []
    for big_t, z_exp in zip(MARTIN_MOYCE_T, MARTIN_MOYCE_Z, strict=True):
        while sim.time < big_t / math.sqrt(2 * g / a):
            sim.step()
            reason = sim.check()
            if reason:
                raise RuntimeError(f"dam break unstable at t = {sim.time}: {reason}")
        z = surge_front(sim.particles().positions, spacing) / a
        err = (z - z_exp) / z_exp
        errors.append((big_t, err))
        print(f"  T = {big_t:.3f}: experiment Z = {z_exp:.3f}, unmesh Z = {z:.3f}, error {100 * err:+.1f} %")
    early = [abs(e) for t, e in errors if t <= 3.0]
    print(f"  largest |error| for T <= 3: {100 * max(early):.1f} % (goal 10 %), mean {100 * np.mean(early):.1f} %; "
          f"{sim.steps} steps in {time.perf_counter() - t0:.0f} s")


_SPLISH_SCRIPT = textwrap.dedent("""
    import json, sys, time
    import pysplishsplash as sph
    scene, stop = sys.argv[1], float(sys.argv[2])
    base = sph.Exec.SimulatorBase()
    base.init(sceneFile=scene, useCache=False, outputDir=sys.argv[3], initialPause=False, useGui=False,
              stopAt=stop)
    base.setValueBool(base.STATE_EXPORT, False)
    steps = [0]
    marks = {}
    def cb():
        steps[0] += 1
        if steps[0] == 3:
            marks["t0"] = time.perf_counter()
            marks["c0"] = time.process_time()
    base.setTimeStepCB(cb)
    base.initSimulation()
    sim = sph.Simulation.getCurrent()
    n = sim.getFluidModel(0).numActiveParticles()
    base.runSimulation()
    wall = time.perf_counter() - marks["t0"]
    cpu = time.process_time() - marks["c0"]
    base.cleanup()
    print(json.dumps({"particles": n, "steps": steps[0] - 3, "wall": wall, "cpu": cpu}))
""")

_BOX_OBJ = """v -0.5 -0.5 -0.5
v 0.5 -0.5 -0.5
v 0.5 0.5 -0.5
v -0.5 0.5 -0.5
v -0.5 -0.5 0.5
v 0.5 -0.5 0.5
v 0.5 0.5 0.5
v -0.5 0.5 0.5
f 1 3 2
f 1 4 3
f 5 6 7
f 5 7 8
f 1 2 6
f 1 6 5
f 4 7 3
f 4 8 7
f 1 5 8
f 1 8 4
f 2 3 7
f 2 7 6
"""


def splishsplash_rate(spacing: float, steps: int, threads: int) -> tuple[int, float, float] | None:
    """(particles, particle-steps per wall second, per CPU second) of SPlisHSPlasH's WCSPH, or None.

    The column of :func:`fluid_block` (SPlisHSPlasH samples fluid blocks on a cubic grid of spacing
    2r = spacing; a block of extent (n + 1/2)·2r holds n particles along that axis), one spacing
    from the tank walls.
    """
    import importlib.util

    if importlib.util.find_spec("pysplishsplash") is None:
        return None
    dt = DT
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "UnitBox.obj").write_text(_BOX_OBJ)
        col = [(n + 0.5) * spacing for n in fluid_block(spacing)]
        scene = {
            "Configuration": {
                "particleRadius": spacing / 2, "numberOfStepsPerRenderUpdate": 1, "density0": RHO0,
                "simulationMethod": 0, "gravitation": [0, -9.81, 0], "timeStepSize": dt, "cflMethod": 0,
                "stiffness": STIFFNESS, "exponent": EXPONENT, "boundaryHandlingMethod": 0, "enableZSort": True,
            },
            "Materials": [{"id": "Fluid", "viscosity": 0.0, "viscosityMethod": 0}],
            "RigidBodies": [{
                "geometryFile": str(d / "UnitBox.obj"), "translation": [TANK[0] / 2, TANK[1] / 2, TANK[2] / 2],
                "rotationAxis": [1, 0, 0], "rotationAngle": 0, "scale": list(TANK), "isDynamic": False,
                "isWall": True, "mapInvert": True, "mapThickness": 0.0, "mapResolution": [40, 30, 15]}],
            "FluidBlocks": [{"denseMode": 0, "start": [spacing, spacing, spacing],
                             "end": [spacing + col[0], spacing + col[1], spacing + col[2]],
                             "translation": [0, 0, 0], "scale": [1, 1, 1]}],
        }
        path = d / "dam.json"
        path.write_text(json.dumps(scene))
        env = dict(os.environ, OMP_NUM_THREADS=str(threads))
        if USER_SPINCOUNT is None:  # SPlisHSPlasH's OpenMP with its own default, not unmesh's
            env.pop("GOMP_SPINCOUNT", None)
        gl = "/usr/lib/x86_64-linux-gnu/libGLdispatch.so.0"
        if Path(gl).exists():
            env["LD_PRELOAD"] = gl
        stop = (steps + 3) * dt * 1.0000001
        res = subprocess.run([sys.executable, "-c", _SPLISH_SCRIPT, str(path), str(stop), str(d / "out")],
                             capture_output=True, text=True, env=env, timeout=3600)
        lines = [ln for ln in res.stdout.splitlines() if ln.startswith("{")]
        if res.returncode != 0 or not lines:
            print(f"SPlisHSPlasH failed (exit {res.returncode}): {res.stderr[-500:]}", file=sys.stderr)
            return None
        out = json.loads(lines[-1])
        ps = out["particles"] * out["steps"]
        return out["particles"], ps / out["wall"], ps / out["cpu"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=60, help="timed steps per case")
    parser.add_argument("--turn", type=int, default=10, help="timed steps per turn of a case (they alternate)")
    parser.add_argument("--spacing", type=float, default=0.01, help="particle spacing (0.01: about 61k particles)")
    parser.add_argument("--threads", default="1,2", help="comma-separated thread counts")
    parser.add_argument("--no-splishsplash", action="store_true")
    parser.add_argument("--no-validation", action="store_true", help="skip the dam-break surge-front validation")
    parser.add_argument("--validation-resolution", type=int, default=20, help="dam break spacing a/N (default 20)")
    parser.add_argument("--shipped-only", action="store_true",
                        help="only the shipped dam break's rate (with and without Verlet lists)")
    args = parser.parse_args()
    threads = [int(t) for t in args.threads.split(",")]
    for t in threads:
        shipped_dam_break(t)
    if args.shipped_only:
        return
    names = {"fluid": "unmesh WCSPH (fluid)", "fluid-ccp": "unmesh WCSPH (fluid, CCP)",
             "elastic": "unmesh WCSPH + elasticity", "splish": "SPlisHSPlasH WCSPH"}
    load0 = os.getloadavg()[0]
    rows = []
    for t in threads:
        rates = unmesh_rates(args.spacing, args.steps, t, ("fluid", "fluid-ccp", "elastic"), args.turn)
        for case, res in rates.items():
            rows.append((names[case], t, *res))
        if not args.no_splishsplash:
            res = splishsplash_rate(args.spacing, args.steps, t)
            if res is not None:
                rows.append((names["splish"], t, *res, float("nan")))
    nx, ny, nz = fluid_block(args.spacing)
    print(f"\n3D dam break, {args.steps} timed steps per case, unmesh cases in turns of {args.turn} (load average {load0:.1f} before, {os.getloadavg()[0]:.1f} after, "
          f"on {os.cpu_count()} CPUs)")
    print(f"fluid: {nx} x {ny} x {nz} particles on a cubic grid of spacing d = {args.spacing} m, h = 2d, in a "
          f"{TANK[0]} x {TANK[1]} x {TANK[2]} m tank; rho0 = {RHO0:g}, K = {STIFFNESS:g} Pa, exponent {EXPONENT:g}, "
          f"dt = {DT:g} s, in both codes (unmesh: analytic walls, artificial viscosity 0.05; SPlisHSPlasH: Akinci "
          "boundary particles, no viscosity)")
    print(f"fluid, CCP / elasticity: a {COLUMN[0]} x {COLUMN[1]} x {COLUMN[2]} m block on the closest packing of "
          f"spacing d (K_e = 1e6/s^2 for the jelly)")
    print(f"{'method':32s} {'threads':>7s} {'particles':>9s} {'M particle-steps/s':>19s} {'per CPU-second':>15s} "
          f"{'neighbours':>10s}")
    for name, t, n, r, rc, nb in rows:
        print(f"{name:32s} {t:7d} {n:9d} {r / 1e6:19.3f} {rc / 1e6:15.3f} {nb:10.1f}")
    for t in threads:
        by = {name: r for name, tt, _n, r, _rc, _nb in rows if tt == t}
        fluid = by[names["fluid"]]
        el = by[names["elastic"]]
        line = (f"{t} thread(s): elastic step costs {fluid / el:.2f}x the fluid step per particle "
                f"({by[names['fluid-ccp']] / el:.2f}x the fluid step on the same closest packing)")
        sp = by.get(names["splish"])
        if sp:
            line += f"; unmesh fluid / SPlisHSPlasH = {fluid / sp:.2f}"
        print(line)
    print("goal: >= 1 M particle-steps/s (fluid, 2 cores), elastic within 3x of fluid, faster than SPlisHSPlasH "
          "at equal threads")
    print("(neighbours: unmesh's mean count within h = 2d, as measured; SPlisHSPlasH's support is 2 spacings as well)")
    if not args.no_validation:
        dam_break_validation(args.validation_resolution)


if __name__ == "__main__":
    main()
