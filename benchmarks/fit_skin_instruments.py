"""`fit-skin` on the NIST forearms as other instruments would report them (issue 35 §3).

Each variant is the NIST subjects' mean spectra resampled (linearly) to another sampling
and range, optionally with the surface's specular reflection added (an SCI instrument):
1 nm and 10 nm steps, 360–750 and 400–700 nm, SCI. Prints ΔE2000 median / max and the RMS
median per variant, and the fit's wall time.

    python benchmarks/fit_skin_instruments.py [--subjects N] [--specular-fit]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from jaxskin import biophysical as bp
from jaxskin import formats
from jaxskin.fitting import skin

VARIANTS = {  # name: (start nm, stop nm, step nm, SCI)
    "as measured (3 nm, 250-2500)": None,
    "1 nm, 380-780": (380, 780, 1, False),
    "10 nm, 400-700": (400, 700, 10, False),
    "5 nm, 360-750": (360, 750, 5, False),
    "2 nm, 400-700": (400, 700, 2, False),
    "10 nm, 360-740, SCI (+k1)": (360, 740, 10, True),
}
# Instrument differences the NIST spectra do not show, as other labs' instruments could
# (stress, not data: each is a guess at a size, not a measurement): a calibration 8 % off,
# light lost at a small port growing towards the red (lateral diffusion: 12 % at 700 nm),
# a 10 nm bandpass (triangle), a 2 nm wavelength offset, an SCI reading of an oilier
# surface (4 % instead of k1 = 2.8 %).
STRESS = {
    "x0.92 (calibration)": lambda wl, R: R * 0.92,
    "x1.08 (calibration)": lambda wl, R: R * 1.08,
    "port loss 0-12 % over 400-700":
        lambda wl, R: R * (1 - 0.12 * np.clip((wl - 400) / 300, 0, 1.2)),
    "10 nm triangle bandpass": lambda wl, R: _bandpass(wl, R, 10.0),
    "+2 nm wavelength offset": lambda wl, R: np.stack([np.interp(wl - 2, wl, r) for r in R]),
    "SCI with 4 % surface": lambda wl, R: R + 0.04,
}


def _bandpass(wl, R, fwhm):
    """`R` seen through a triangular bandpass of `fwhm` nm."""
    fine = np.arange(wl[0], wl[-1] + 0.5, 1.0)
    Rf = np.stack([np.interp(fine, wl, r) for r in R])
    half = int(fwhm)
    k = np.r_[np.arange(1, half + 1), np.arange(half - 1, 0, -1)].astype(float)
    k /= k.sum()
    out = np.stack([np.convolve(np.pad(r, half - 1, mode="edge"), k, "valid") for r in Rf])
    return np.stack([np.interp(wl, fine, r) for r in out])


def variant(wl, R, spec):
    """The spectra `R (m, n)` at `wl` as the instrument `spec` reports them."""
    if spec is None:
        return wl, R
    lo, hi, step, sci = spec
    grid = np.arange(lo, hi + step / 2, step, dtype=np.float64)
    out = np.stack([np.interp(grid, wl, r) for r in R])
    return grid, out + (bp.K1 if sci else 0.0)


def main(argv=None):
    """Fit every variant; print one line each."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--subjects", type=int, default=100)
    ap.add_argument("--only", default="")
    ap.add_argument("--stress", action="store_true", help="the STRESS variants instead")
    args = ap.parse_args(argv)
    names, wl, R = formats.read_spectra(formats.data_dir() / "spectra" / formats.NIST_FILE)
    names, R = names[:args.subjects], R[:args.subjects]
    if args.stress:
        keep = (wl >= 360) & (wl <= 800)
        wl, R = wl[keep], R[:, keep]
        for label, f in STRESS.items():
            if args.only and args.only not in label:
                continue
            specular = label.startswith("SCI")
            t0 = time.perf_counter()
            res = skin.fit(names, wl, f(wl, R), specular=specular)
            print(f"{label:32s} fit {'SCI' if specular else 'SCE'}: ΔE00 median "
                  f"{np.median(res.dE2000):.2f} max {res.dE2000.max():.2f} "
                  f"({res.names[int(np.argmax(res.dE2000))]}); RMS median "
                  f"{np.median(res.rms):.4f}; {time.perf_counter() - t0:.0f} s", flush=True)
        return
    for label, spec in VARIANTS.items():
        if args.only and args.only not in label:
            continue
        w, Rv = variant(wl, R, spec)
        sci = bool(spec and spec[3])
        for specular in ((False, True) if sci else (False,)):
            t0 = time.perf_counter()
            kw = {"specular": specular} if "specular" in skin.fit.__code__.co_varnames else {}
            if specular and not kw:
                continue
            res = skin.fit(names, w, Rv, **kw)
            dt = time.perf_counter() - t0
            print(f"{label:32s} fit {'SCI' if specular else 'SCE'}: ΔE00 median "
                  f"{np.median(res.dE2000):.2f} max {res.dE2000.max():.2f} "
                  f"({res.names[int(np.argmax(res.dE2000))]}); RMS median "
                  f"{np.median(res.rms):.4f}; {dt:.0f} s", flush=True)


if __name__ == "__main__":
    main()
