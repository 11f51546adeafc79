"""The simulation runner shared by SPH, thin shells and FEM.

A simulation subclasses :class:`Simulation`; :func:`run` owns the time loop,
frame output, ``summary.json``, the ``frames.json`` manifest of written files,
checkpoints and ``--resume``, refusing non-empty output folders without ``force``, instability
detection (keeping the last good frame), Ctrl-C and the progress bar. The command
line side is in :mod:`unmesh.sim.cli`.

Example
-------
>>> import tempfile
>>> class Fall(Simulation):
...     name = "fall"
...     def __init__(self): self.time, self.y, self.v = 0.0, 1.0, 0.0
...     def step(self):
...         self.v -= 9.81 * 0.01; self.y += 0.01 * self.v; self.time += 0.01; return 0.01
...     def check(self): return None
...     def write_frame(self, outdir, frame): return []
...     def frame_record(self): return {"height": self.y}
...     def state_dict(self): return {"time": self.time, "y": self.y, "v": self.v}
...     def load_state_dict(self, s): self.time, self.y, self.v = s["time"], s["y"], s["v"]
>>> result = run(Fall(), tempfile.mkdtemp(), RunSettings(duration=0.1, fps=20), progress=False)
>>> result.status, result.frames
('completed', 2)
"""

from unmesh.sim.runner import MANIFEST, RunResult, RunSettings, Simulation, read_manifest, read_summary, run

__all__ = ["MANIFEST", "RunResult", "RunSettings", "Simulation", "read_manifest", "read_summary", "run"]
