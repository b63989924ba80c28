"""Mixtures and colour matching: the two-constant Kubelka–Munk rule against a hand
computation, its gradients, `jaxskin mix` against the rule, `jaxskin match` recovering known
concentrations (opaque, as a film, from CIELAB), a target out of gamut, and the bad-input
table (exit 2, one line, nothing written)."""

import hashlib
import json
import math
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled
from jax.test_util import check_grads

from jaxskin import mixture
from jaxskin.cli import main

ROOT = Path(__file__).resolve().parent.parent
MATERIALS = ROOT / "data" / "materials"
PIGMENTS = ["pigment_white", "pigment_red", "pigment_yellow", "pigment_black"]
NIST = ROOT / "data" / "spectra" / "nist_skin_reflectance_M38597.csv"


def _r_inf_by_hand(S, K):
    q = K / S
    return 1.0 + q - math.sqrt(q * q + 2.0 * q)


def _film_by_hand(S, K, X, Rg):
    """Kubelka's hyperbolic form (a, b), then the layer over an opaque background."""
    a = 1.0 + K / S
    b = math.sqrt(a * a - 1.0)
    sh, ch = math.sinh(b * S * X), math.cosh(b * S * X)
    R0, T = sh / (a * sh + b * ch), b / (a * sh + b * ch)
    return R0 + T * T * Rg / (1.0 - R0 * Rg)


def test_the_rule_against_a_hand_computation(x64):
    S = [[10.0, 20.0, 30.0], [100.0, 50.0, 5.0]]
    K = [[1.0, 2.0, 3.0], [0.5, 0.5, 50.0]]
    S_mix, K_mix = mixture.mix(S, K, [0.25, 0.75])
    # 0.25·10 + 0.75·100 = 77.5, ...; 0.25·3 + 0.75·50 = 38.25
    np.testing.assert_allclose(S_mix, [77.5, 42.5, 11.25], rtol=1e-15)
    np.testing.assert_allclose(K_mix, [0.625, 0.875, 38.25], rtol=1e-15)
    R = mixture.reflectance(S, K, [0.25, 0.75])
    np.testing.assert_allclose(R, [_r_inf_by_hand(77.5, 0.625), _r_inf_by_hand(42.5, 0.875),
                                   _r_inf_by_hand(11.25, 38.25)], rtol=1e-12)
    film = mixture.reflectance(S, K, [0.25, 0.75], 0.02, 0.3)
    np.testing.assert_allclose(film, [_film_by_hand(77.5, 0.625, 0.02, 0.3),
                                      _film_by_hand(42.5, 0.875, 0.02, 0.3),
                                      _film_by_hand(11.25, 38.25, 0.02, 0.3)], rtol=1e-12)
    # a zero drops a component; the rule does not renormalise
    np.testing.assert_allclose(mixture.mix(S, K, [0.0, 1.0])[0], S[1], rtol=0)
    with pytest.raises(ValueError, match="one value per row"):
        mixture.mix(S, K, [1.0])


@pytest.mark.parametrize("c", [[0.2, 0.5, 0.3], [0.0, 0.4, 0.6], [1.0, 0.0, 0.0]])
def test_gradients_of_the_mixture(x64, c):
    """Ordinary and zero concentrations: the rule, and the opaque and film reflectance."""
    rng = np.random.default_rng(1)
    S = jnp.asarray(rng.uniform(5, 300, (3, 4)))
    K = jnp.asarray(rng.uniform(0.1, 500, (3, 4)))
    c = jnp.asarray(c)
    check_grads(lambda s, k, c: jnp.stack(mixture.mix(s, k, c)), (S, K, c), order=2,
                modes=("fwd", "rev"), eps=1e-6)
    check_grads(lambda c: mixture.reflectance(S, K, c), (c,), order=2, modes=("fwd", "rev"),
                eps=1e-6)
    # first order for the film (km.layer's own second-order checks are in test_km.py)
    check_grads_scaled(lambda c, x: mixture.reflectance(S, K, c, x, 0.4), (c, 0.01),
                       (0.01, 0.001), order=1)
    g = jax.grad(lambda c: mixture.reflectance(S, K, c).sum())(c)
    assert np.all(np.isfinite(g))


def _run(argv, capsys):
    capsys.readouterr()
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:
        code = e.code
    out = capsys.readouterr()
    return code, out.out, out.err


def test_mix_writes_the_rule_and_renders(tmp_path, capsys):
    from jaxskin import cosmetics, spectral

    code, out, err = _run(["mix", MATERIALS / "pigment_white.json:0.7", "pigment_red:0.2",
                           "pigment_yellow:0.1", "-o", tmp_path, "--name", "shade"], capsys)
    assert code == 0, err
    doc = json.loads((tmp_path / "shade.json").read_text())
    files = [json.loads((MATERIALS / f"{n}.json").read_text()) for n in PIGMENTS[:3]]
    for key in ("S_per_mm", "K_per_mm"):  # the sum by hand, from the files
        hand = sum(c * np.array(f[key]) for c, f in zip((0.7, 0.2, 0.1), files, strict=True))
        np.testing.assert_allclose(doc[key], hand, rtol=1e-12)
    assert doc["mixture"]["concentrations"] == {"pigment_white": 0.7, "pigment_red": 0.2,
                                                "pigment_yellow": 0.1}
    m = cosmetics.load_material(tmp_path / "shade.json", spectral.Grid())
    assert np.all(np.isfinite(m.S)) and not m.extrapolated.any()


def test_mix_resamples_components_on_other_grids(tmp_path, capsys):
    white = json.loads((MATERIALS / "pigment_white.json").read_text())
    red = json.loads((MATERIALS / "pigment_red.json").read_text())
    keep = [i for i, w in enumerate(red["wavelength_nm"]) if 400 <= w <= 700 and w % 10 == 0]
    coarse = {**red, "name": "red10", **{k: [red[k][i] for i in keep] for k in
                                         ("wavelength_nm", "S_per_mm", "K_per_mm")}}
    del coarse["identifiable"]
    (tmp_path / "red10.json").write_text(json.dumps(coarse))
    code, out, err = _run(["mix", MATERIALS / "pigment_white.json:0.6",
                           tmp_path / "red10.json:0.4", "-o", tmp_path / "o"], capsys)
    assert code == 0, err
    assert "different wavelength grids" in err and "400-700 nm" in err
    doc = json.loads((tmp_path / "o" / "mix_pigment_white_red10.json").read_text())
    wl = np.array(doc["wavelength_nm"])
    assert wl[0] == 400 and wl[-1] == 700 and len(wl) == 61  # white's 5 nm steps, within
    i, j = doc["wavelength_nm"].index(550.0), white["wavelength_nm"].index(550.0)
    assert doc["S_per_mm"][i] == pytest.approx(0.6 * white["S_per_mm"][j]
                                               + 0.4 * red["S_per_mm"][red["wavelength_nm"]
                                                                       .index(550.0)])
    assert "extrapolate" not in doc
    assert "not the renderer's 380-780 nm" in err


def test_mix_scales_a_rounded_formula_to_one(tmp_path, capsys):
    """Shares that sum to 1 within 0.001 (a formula rounded to 4 decimals) are divided by
    their sum, with a note; further off is refused (the bad-input table)."""
    code, out, err = _run(["mix", f"{W}:0.6667", f"{R}:0.3332", "-o", tmp_path], capsys)
    assert code == 0, err
    assert "sum to 0.9999: each divided by that sum" in err
    doc = json.loads((tmp_path / "mix_pigment_white_pigment_red.json").read_text())
    shares = doc["mixture"]["concentrations"]
    assert shares["pigment_white"] == pytest.approx(0.6667 / 0.9999, rel=1e-12)
    assert sum(shares.values()) == pytest.approx(1.0, abs=1e-15)


def test_weight_fractions_by_hand(x64, tmp_path, capsys):
    # 0.5 g at 4 g/cm3 is 0.125 cm3, 0.5 g at 1 g/cm3 is 0.5 cm3: 20 % and 80 % by volume
    np.testing.assert_allclose(mixture.volume_fractions([0.5, 0.5], [4.0, 1.0]), [0.2, 0.8],
                               rtol=1e-15)
    np.testing.assert_allclose(mixture.weight_fractions([0.2, 0.8], [4.0, 1.0]), [0.5, 0.5],
                               rtol=1e-15)
    code, out, err = _run(["mix", f"{W}:0.5", f"{R}:0.5", "--density", "pigment_white=4",
                           "--density", "pigment_red=1", "-o", tmp_path, "--name", "w"], capsys)
    assert code == 0, err
    doc = json.loads((tmp_path / "w.json").read_text())
    assert doc["mixture"]["concentrations"] == pytest.approx(
        {"pigment_white": 0.2, "pigment_red": 0.8}, rel=1e-14)
    assert doc["mixture"]["weight_fractions"] == {"pigment_white": 0.5, "pigment_red": 0.5}
    white, red = (json.loads((MATERIALS / f"{n}.json").read_text()) for n in PIGMENTS[:2])
    np.testing.assert_allclose(doc["K_per_mm"], 0.2 * np.array(white["K_per_mm"])
                               + 0.8 * np.array(red["K_per_mm"]), rtol=1e-12)


def _target(tmp_path, c, names=PIGMENTS, thickness=None, background=None):
    """A target spectrum mixed from the shipped pigments at `c` (float64), as a CSV."""
    from jaxskin.fitting.match import read_components

    comps = read_components([MATERIALS / f"{n}.json" for n in names])
    with jax.enable_x64(True):
        R = np.asarray(mixture.reflectance(comps.S, comps.K, np.asarray(c), thickness,
                                           background))
    path = tmp_path / "target.csv"
    path.write_text("wavelength_nm,R\n" + "".join(
        f"{w:g},{r:.10f}\n" for w, r in zip(comps.wavelength_nm, R, strict=True)))
    return path, comps, R


def test_match_recovers_known_concentrations(tmp_path, capsys):
    """Opaque, four components: within 0.01 and dE2000 <= 0.1 (compiles one vmapped LM:
    about 8 s)."""
    c = [0.62, 0.07, 0.25, 0.06]
    path, _, _ = _target(tmp_path, c)
    rho = [4.0, 5.2, 4.0, 5.1]  # titanium dioxide, haematite, goethite, magnetite (g/cm3)
    code, out, err = _run(["match", path, "--from", ",".join(PIGMENTS), "-o", tmp_path / "o",
                           *(f"--density={n}={r}" for n, r in zip(PIGMENTS, rho, strict=True))],
                          capsys)
    assert code == 0, err
    doc = json.loads((tmp_path / "o" / "target_match.json").read_text())
    got = [doc["concentrations"][n] for n in PIGMENTS]
    assert np.max(np.abs(np.subtract(got, c))) < 0.01, got
    by_weight = np.multiply(got, rho) / np.dot(got, rho)
    assert [doc["concentrations_by_weight"][n] for n in PIGMENTS] == pytest.approx(by_weight)
    assert doc["dE2000"] <= 0.1 and doc["in_gamut"] and doc["opaque"]
    assert sum(got) == pytest.approx(1.0, abs=1e-12)
    assert (tmp_path / "o" / "target_match.png").stat().st_size > 10_000
    assert "to make it: jaxskin mix" in out and "warning" not in err


def test_match_of_a_target_measured_with_its_surface(x64):
    """A target read specular included (Saunderson's R_m = k1 + (1-k1)(1-k2) R / (1-k2 R),
    written out here, k1 0.04, k2 0.6): `saunderson=(k1, k2)` recovers the recipe (within
    0.01, dE2000 <= 0.1); compared as it is, the surface's light is read as white pigment
    (off by more than 0.03)."""
    from jaxskin.fitting import match

    c = np.array([0.62, 0.07, 0.25, 0.06])
    wl = np.arange(380.0, 781.0, 5.0)
    comps = match.read_components([MATERIALS / f"{n}.json" for n in PIGMENTS])
    R = np.asarray(mixture.reflectance(comps.S, comps.K, c))
    k1, k2 = 0.04, 0.6
    R_m = k1 + (1 - k1) * (1 - k2) * R / (1 - k2 * R)
    r = match.fit(comps, wl, R_m, starts=6, saunderson=(k1, k2))
    assert np.max(np.abs(r.concentrations - c)) < 0.01 and r.dE2000 <= 0.1, r.concentrations
    assert r.saunderson == (k1, k2)
    plain = match.fit(comps, wl, R_m, starts=6)
    assert np.max(np.abs(plain.concentrations - c)) > 0.03, plain.concentrations
    assert plain.saunderson is None


def test_match_of_a_film_over_a_background_both_read_with_their_surface(x64):
    """A 8 µm film over a background, the film and the background alone both read specular
    included (written out: k1 0.04, k2 0.6): with `saunderson` the background's reading is
    made internal too, and the recipe comes back within 0.01."""
    from jaxskin.fitting import match

    c = np.array([0.5, 0.2, 0.3])
    k1, k2 = 0.04, 0.6
    wl = np.arange(380.0, 781.0, 5.0)
    Rg = np.linspace(0.2, 0.5, 81)  # internal
    comps = match.read_components([MATERIALS / f"{n}.json" for n in PIGMENTS[:3]])
    R = np.asarray(mixture.reflectance(comps.S, comps.K, c, 0.008, Rg))

    def seen(r):
        return k1 + (1 - k1) * (1 - k2) * r / (1 - k2 * r)

    r = match.fit(comps, wl, seen(R), thickness_mm=0.008, background=(wl, seen(Rg)),
                  starts=6, saunderson=(k1, k2))
    assert np.max(np.abs(r.concentrations - c)) < 0.01 and r.dE2000 <= 0.1, r.concentrations


def test_match_recovers_a_film_and_its_thickness(x64):
    """Concentrations within 0.01 and the thickness within 2 % (compiles the film's LM,
    km.layer inside, twice: 14-21 s on two shared cores)."""
    from jaxskin.fitting import match

    c = np.array([0.5, 0.2, 0.3])
    Rg = np.linspace(0.2, 0.5, 81)
    wl = np.arange(380.0, 781.0, 5.0)
    comps = match.read_components([MATERIALS / f"{n}.json" for n in PIGMENTS[:3]])
    R = np.asarray(mixture.reflectance(comps.S, comps.K, c, 0.008, Rg))
    r = match.fit(comps, wl, R, thickness_mm="fit", background=(wl, Rg), starts=6)
    assert np.max(np.abs(r.concentrations - c)) < 0.01, r.concentrations
    assert r.thickness_mm == pytest.approx(0.008, rel=0.02)
    assert r.dE2000 <= 0.1 and not r.hides_background
    # an opaque target: the film hides the background, and the fit says its thickness is
    # only a lower bound
    opaque = np.asarray(mixture.reflectance(comps.S, comps.K, c))
    r = match.fit(comps, wl, opaque, thickness_mm="fit", background=(wl, Rg), starts=6)
    assert r.hides_background and r.dE2000 <= 0.1
    assert np.max(np.abs(r.concentrations - c)) < 0.01, r.concentrations


def test_match_from_cielab(x64, tmp_path, capsys):
    """Three components: two free fractions, three coordinates, one answer. The CIELAB of
    the target is colour-science's (the fit's own `lab` is only its loss)."""
    import colour

    from jaxskin.fitting import match

    c = np.array([0.7, 0.1, 0.2])
    comps = match.read_components([MATERIALS / f"{n}.json" for n in PIGMENTS[:3]])
    R = np.asarray(mixture.reflectance(comps.S, comps.K, c))
    sd = colour.SpectralDistribution(R, comps.wavelength_nm)
    cmfs = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"]
    xyz = colour.sd_to_XYZ(sd, cmfs, colour.SDS_ILLUMINANTS["D65"], method="ASTM E308") / 100
    white = colour.CCS_ILLUMINANTS["CIE 1964 10 Degree Standard Observer"]["D65"]
    lab = colour.XYZ_to_Lab(xyz, white)
    r = match.fit(comps, target_lab=lab, starts=6)
    assert np.max(np.abs(r.concentrations - c)) < 0.01, r.concentrations
    assert r.dE2000 <= 0.1
    code, out, err = _run(["match", "--lab", ",".join(f"{v:.4f}" for v in lab), "--from",
                           ",".join(PIGMENTS[:3]), "-o", tmp_path, "--name", "shade",
                           "--starts", "6"], capsys)
    assert code == 0, err
    doc = json.loads((tmp_path / "shade_match.json").read_text())
    assert doc["target"] == {"Lab": pytest.approx(list(lab), abs=1e-4)}
    got = [doc["concentrations"][n] for n in PIGMENTS[:3]]
    assert np.max(np.abs(np.subtract(got, c))) < 0.01 and doc["dE2000"] <= 0.1
    assert "R_target" not in doc and "metamerism" not in doc
    # the fit's differentiable CIELAB agrees with colour-science's on the same weights
    grid, W = match.colour_weights(380, 780)
    # (measured 0.008 in b*: colour's tabulated white point is rounded to 4 decimals in xy)
    np.testing.assert_allclose(match.lab(jnp.asarray(R), jnp.asarray(W)), lab, atol=0.02)


@pytest.mark.parametrize("level", [0.4, 0.005, 0.0])
def test_gradients_of_the_loss_colour(x64, level):
    """The fit's CIELAB: an ordinary grey, one below the cube root's linear part
    (Y < 0.0089), and black, where the cube root's derivative would be infinite."""
    from jaxskin.fitting import match

    _, W = match.colour_weights(380, 780)
    R = jnp.asarray(level * (1 + 0.2 * np.sin(np.arange(W.shape[0]))))  # black: all 0
    check_grads(lambda r: match.lab(r, jnp.asarray(W)), (R,), order=1, modes=("fwd", "rev"),
                eps=1e-7)
    g = jax.jacobian(lambda r: match.lab(r, jnp.asarray(W)))(R)
    assert np.all(np.isfinite(g))


def test_out_of_gamut_gives_the_closest_match_and_says_so(tmp_path, capsys):
    """White and red cannot make a skin colour: the closest mixture (checked against every
    share on a fine line, colour-science CIELAB) and a warning naming its dE2000."""
    import colour

    from jaxskin.fitting import match

    code, out, err = _run(["match", NIST, "--spectrum", "subject_38", "--from",
                           "pigment_white,pigment_red", "--spectral-weight", "0", "-o",
                           tmp_path], capsys)
    assert code == 0, err
    doc = json.loads((tmp_path / "nist_skin_reflectance_M38597_subject_38_match.json")
                     .read_text())
    assert not doc["in_gamut"] and doc["dE2000"] > 1
    lines = err.splitlines()
    assert len(lines) == 1 and "outside what these components can mix" in lines[0]
    assert f"dE2000 {doc['dE2000']:.2f}" in lines[0]
    comps = match.read_components([MATERIALS / "pigment_white.json",
                                   MATERIALS / "pigment_red.json"])
    grid, W = match.colour_weights(380, 780)
    S = np.stack([np.interp(grid, comps.wavelength_nm, s) for s in comps.S])
    K = np.stack([np.interp(grid, comps.wavelength_nm, k) for k in comps.K])
    white_xy = colour.XYZ_to_xy(W.sum(0))
    t = np.linspace(0, 1, 2001)[:, None]
    q = (t * K[0] + (1 - t) * K[1]) / (t * S[0] + (1 - t) * S[1])
    lab = colour.XYZ_to_Lab((1 + q - np.sqrt(q * q + 2 * q)) @ W, white_xy)
    best = float(np.min(np.linalg.norm(lab - doc["Lab_target"], axis=1)))
    got = float(np.linalg.norm(np.subtract(doc["Lab_match"], doc["Lab_target"])))
    assert got <= best + 1e-3, (got, best)


# ---------------------------------------------------------------- bad input

def _write(tmp, name, text):
    (tmp / name).write_text(text)
    return str(tmp / name)


def _film_material(tmp):
    doc = json.loads((MATERIALS / "pigment_red.json").read_text())
    doc["S_film"], doc["K_film"] = doc.pop("S_per_mm"), doc.pop("K_per_mm")
    return _write(tmp, "film.json", json.dumps(doc))


W = str(MATERIALS / "pigment_white.json")
R = str(MATERIALS / "pigment_red.json")
FROM = ["--from", "pigment_white,pigment_red"]
ONE = "wavelength_nm,R\n" + "".join(f"{w},0.4\n" for w in range(380, 781, 10))

CASES = {
    "mix-not-a-number": lambda t: ["mix", f"{W}:x", f"{R}:0.5", "-o", "out"],
    "mix-negative": lambda t: ["mix", f"{W}:1.1", f"{R}:-0.1", "-o", "out"],
    "mix-over-one": lambda t: ["mix", f"{W}:1.5", "-o", "out"],
    "mix-nan": lambda t: ["mix", f"{W}:nan", f"{R}:0.5", "-o", "out"],
    "mix-no-colon": lambda t: ["mix", W, "-o", "out"],
    "mix-missing-file": lambda t: ["mix", f"{W}:0.5", "nope.json:0.5", "-o", "out"],
    "mix-sum-not-one": lambda t: ["mix", f"{W}:0.5", f"{R}:0.4", "-o", "out"],
    "mix-film-material": lambda t: ["mix", f"{W}:0.5", f"{_film_material(t)}:0.5", "-o",
                                    "out"],
    "mix-a-measurement": lambda t: ["mix", f"{W}:0.5", f"{ROOT}/data/pigments/"
                                    "pigment_red.csv:0.5", "-o", "out"],
    "mix-twice": lambda t: ["mix", f"{W}:0.5", f"{W}:0.5", "-o", "out"],
    "mix-bad-name": lambda t: ["mix", f"{W}:0.5", f"{R}:0.5", "-o", "out", "--name", "a/b"],
    "mix-out-is-a-file": lambda t: ["mix", f"{W}:0.5", f"{R}:0.5", "-o",
                                    _write(t, "f.txt", "x")],
    "match-no-target": lambda t: ["match", *FROM, "-o", "out"],
    "match-target-and-lab": lambda t: ["match", _write(t, "t.csv", ONE), "--lab", "50,0,0",
                                       *FROM, "-o", "out"],
    "match-bad-lab": lambda t: ["match", "--lab", "50,0", *FROM, "-o", "out"],
    "match-lab-range": lambda t: ["match", "--lab", "150,0,0", *FROM, "-o", "out"],
    "match-many-spectra": lambda t: ["match", str(NIST), *FROM, "-o", "out"],
    "match-unknown-spectrum": lambda t: ["match", str(NIST), "--spectrum", "subject_101",
                                         *FROM, "-o", "out"],
    "match-thickness-alone": lambda t: ["match", _write(t, "t.csv", ONE), "--thickness",
                                        "0.01", *FROM, "-o", "out"],
    "match-bad-thickness": lambda t: ["match", _write(t, "t.csv", ONE), "--background", "0.5",
                                      "--thickness", "-1", *FROM, "-o", "out"],
    "match-bad-background": lambda t: ["match", _write(t, "t.csv", ONE), "--background", "2",
                                       *FROM, "-o", "out"],
    "match-missing-background": lambda t: ["match", _write(t, "t.csv", ONE), "--background",
                                           "bg.csv", *FROM, "-o", "out"],
    "match-missing-component": lambda t: ["match", _write(t, "t.csv", ONE), "--from",
                                          f"{W},nope.json", "-o", "out"],
    "match-film-component": lambda t: ["match", _write(t, "t.csv", ONE), "--from",
                                       f"{W},{_film_material(t)}", "-o", "out"],
    "match-empty-item": lambda t: ["match", _write(t, "t.csv", ONE), "--from", f"{W},",
                                   "-o", "out"],
    "match-narrow-target": lambda t: ["match", _write(t, "t.csv", "wavelength_nm,R\n" + "".join(
        f"{w},0.4\n" for w in range(450, 651, 10))), *FROM, "-o", "out"],
    "match-reflectance-above-one": lambda t: ["match", _write(t, "t.csv", ONE.replace(
        "500,0.4", "500,1.4")), *FROM, "-o", "out"],
    "match-spectrum-with-lab": lambda t: ["match", "--lab", "50,0,0", "--spectrum", "x",
                                          *FROM, "-o", "out"],
    "mix-density-missing": lambda t: ["mix", f"{W}:0.5", f"{R}:0.5", "--density",
                                      "pigment_white=4", "-o", "out"],
    "mix-density-bad": lambda t: ["mix", f"{W}:0.5", f"{R}:0.5", "--density",
                                  "pigment_white=-4", "--density", "pigment_red=5", "-o", "out"],
    "match-density-unknown": lambda t: ["match", "--lab", "50,0,0", *FROM, "-o", "out",
                                        "--density", "titanium=4"],
    "match-bad-starts": lambda t: ["match", "--lab", "50,0,0", *FROM, "-o", "out",
                                   "--starts", "0"],
}


def _snapshot(folder: Path) -> dict:
    out = {}
    for dirpath, dirs, files in os.walk(folder):
        for name in files:
            p = Path(dirpath, name)
            out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
        out.update({str(Path(dirpath, d)): "dir" for d in dirs})
    return out


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_one_line_exit_2_and_writes_nothing(case, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = CASES[case](tmp_path)
    before = _snapshot(tmp_path)
    code, out, err = _run(argv, capsys)
    assert code == 2, (code, err)
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxskin: error: "), err
    assert _snapshot(tmp_path) == before


def test_what_the_lines_say(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for case, words in (("mix-film-material", "film.json: key 'S_film': a material of "
                         "unknown thickness"),
                        ("mix-sum-not-one", "sum to 0.9"),
                        ("mix-negative", "must be a volume fraction in [0, 1]"),
                        ("match-many-spectra", "choose one with --spectrum"),
                        ("match-narrow-target", "needs 400-700 nm")):
        _, _, err = _run(CASES[case](tmp_path), capsys)
        assert words in err, (case, err)
