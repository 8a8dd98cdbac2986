"""benchmarks/viscoelastic/carriers.py at CI size: the bending beam loaded for 6 kyr and unloaded for 3
at 30 x 20 cells with the stress as P2 fields follows the particles' curve (4.8 % apart at most, of
the particles' deflection at the end of the loading), and the table names every carrier."""

import numpy as np

from benchmarks.viscoelastic import bending_beam, carriers


def test_fields_follow_the_particles(tmp_path):
    curves = {label: bending_beam.run_case((30, 20), out=tmp_path / str(index), t_load=6.0, t_end=9.0, stress=stress)
              for index, (label, stress) in enumerate(list(carriers.CARRIERS.items())[:2])}
    particles, fields = curves.values()
    scale = np.interp(6.0, particles.t, particles.w)
    assert scale > 20.0 and np.all(np.diff(fields.w[fields.t <= 6.0]) > 0.0)  # m: the beam sinks while loaded
    assert np.max(np.abs(fields.w - particles.w)) < 0.06 * scale
    assert np.isfinite(fields.cpu_per_step) and fields.cpu_per_step > 0.0
    text = carriers.table(curves, None, t_load=6.0, t_end=9.0)
    assert all(f"| {label} |" in text for label in curves)
