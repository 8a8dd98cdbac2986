"""Lab-note helper: 1D estimate of how an air film on a 100 km plate (1e23 Pa s, air 1e19) lowers the
plate's bending stiffness int eta (z - z_n)^2 dz, with the film sharp or spread over the plate's
top cell by the geometric mean of the cell fraction (DG0), for several cell sizes.

    python -m benchmarks.schmeling.log.film_stiffness
"""

import numpy as np

z = np.linspace(0.0, 100.0, 400001)


def stiffness(log_eta: np.ndarray) -> float:
    eta = 10.0 ** log_eta
    neutral = np.trapz(eta * z, z) / np.trapz(eta, z)
    return float(np.trapz(eta * (z - neutral) ** 2, z))


intact = stiffness(np.full_like(z, 23.0))
for cell in (25.0, 16.67, 12.5, 6.25, 2.0):
    row = []
    for film in (1.0, 2.0, 3.0):
        if film >= cell:
            profile = np.where(z > 100.0 - film, 19.0, 23.0)
        else:
            profile = np.where(z > 100.0 - cell, 23.0 - 4.0 * film / cell, 23.0)
        row.append(f"film {film:g} km: {stiffness(profile) / intact:.2f}")
    print(f"cell {cell:5.2f} km, geometric DG0: " + "  ".join(row))
print(f"sharp 3 km film: {stiffness(np.where(z > 97.0, 19.0, 23.0)) / intact:.2f}")
