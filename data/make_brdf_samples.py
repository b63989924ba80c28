"""Make data/brdf/skin_samples.csv: synthetic BRDF samples of the `skin` Lafortune preset.

4,000 random direction pairs (cosine-distributed incidence and exitance, polar angles up to
85°), values of `jaxskin.shading.lafortune.skin()` times (1 + 2 % Gaussian noise), seed 1997.
Not a measurement: an example of the format that `jaxskin fit-brdf` reads, with a known truth.

    python data/make_brdf_samples.py
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from jaxskin.io import atomic_write
from jaxskin.shading import lafortune

OUT = Path(__file__).resolve().parent / "brdf" / "skin_samples.csv"


def random_directions(rng, m, max_theta_deg=85.0):
    """Cosine-distributed unit vectors in the upper hemisphere, polar angle <= max_theta."""
    s_max = np.sin(np.radians(max_theta_deg)) ** 2
    r2 = rng.uniform(0, s_max, m)
    phi = rng.uniform(0, 2 * np.pi, m)
    r = np.sqrt(r2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - r2)], axis=-1)


def samples(m=4000, noise=0.02, seed=1997):
    """(wi, wo, f_noisy, f_true) from the skin preset."""
    rng = np.random.default_rng(seed)
    wi, wo = random_directions(rng, m), random_directions(rng, m)
    with jax.enable_x64(True):
        p = lafortune.skin(np.float64)
        f = np.asarray(lafortune.brdf(p, wi, wo))
    return wi, wo, f * (1 + noise * rng.normal(size=f.shape)), f


def held_out_error(params, m=20000, seed=12345):
    """Relative RMS error per channel of `params` against the true (preset) BRDF on `m` new
    direction pairs: how well a fit generalises beyond its samples."""
    rng = np.random.default_rng(seed)
    wi, wo = random_directions(rng, m), random_directions(rng, m)
    with jax.enable_x64(True):
        true = np.asarray(lafortune.brdf(lafortune.skin(np.float64), wi, wo))
        fitted = lafortune.Lafortune(*(np.asarray(a, np.float64) for a in params))
        got = np.asarray(lafortune.brdf(fitted, wi, wo))
    return np.sqrt(np.mean((got - true) ** 2, axis=0) / np.mean(true**2, axis=0))


def main():
    wi, wo, f, _ = samples()
    deg = np.degrees
    with atomic_write(OUT, "w") as fh:
        fh.write("# synthetic: skin preset (pbrt-v1 Lafortune fit) + 2 % noise; "
                 "made by data/make_brdf_samples.py\n")
        fh.write("theta_in_deg,phi_in_deg,theta_out_deg,phi_out_deg,R,G,B\n")
        for a, b, v in zip(wi, wo, f, strict=True):
            row = [deg(np.arccos(a[2])), deg(np.arctan2(a[1], a[0])), deg(np.arccos(b[2])),
                   deg(np.arctan2(b[1], b[0])), *v]
            fh.write(",".join(f"{x:.6g}" for x in row) + "\n")


if __name__ == "__main__":
    main()
