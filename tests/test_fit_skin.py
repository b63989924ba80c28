"""`jaxskin fit-skin`: the biophysical model fitted to measured and synthetic spectra; the
spectra readers; CIEDE2000 against colour-science used another way; bad inputs."""

import csv
import warnings

import jax
import numpy as np
import pytest

from jaxskin import biophysical as bp
from jaxskin import formats
from jaxskin.cli import main
from jaxskin.fitting import skin

NIST = formats.data_dir() / "spectra" / formats.NIST_FILE
SUBJECTS = (1, 28, 42, 61, 97)  # 28: the NIST fit's worst ΔE; 42 the lightest; 61 dark


def _wide(path, names, wl, R, fmt="{:.4f}"):
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["wavelength_nm", *names])
        for i, x in enumerate(wl):
            w.writerow([f"{x:g}", *(fmt.format(r[i]) for r in R)])
    return path


def test_nist_layout_is_read_as_the_subjects_means():
    names, wl, R = formats.read_spectra(NIST)
    assert names[:2] == ["subject_1", "subject_2"] and len(names) == 100
    want_wl, want = formats._spectra.nist_table()  # the renderer's own reader of the same file
    np.testing.assert_array_equal(wl, want_wl)
    np.testing.assert_array_equal(R, want)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """`jaxskin fit-skin` on five NIST subjects written as a wide CSV (one compile, ~30 s
    under load; the synthetic test below reuses the compiled program)."""
    tmp = tmp_path_factory.mktemp("fit")
    names, wl, R = formats.read_spectra(NIST)
    pick = [s - 1 for s in SUBJECTS]
    src = _wide(tmp / "five.csv", [names[k] for k in pick], wl, R[pick])
    assert main(["fit-skin", str(src), "-o", str(tmp / "out")]) == 0
    return tmp / "out", [names[k] for k in pick]


@pytest.mark.slow
def test_fit_skin_on_nist_subjects(fitted):
    out, names = fitted
    with (out / "five_fit.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [r["name"] for r in rows] == names
    assert list(rows[0]) == ["name", *bp.PARAMS, "rms", "dE2000", "converged", "steps",
                             *(f"{p}_sd" for p in bp.PARAMS), "corr_melanin_epidermis",
                             "specular"]
    assert {r["specular"] for r in rows} == {"excluded"}  # the default: SCE
    dE = np.array([float(r["dE2000"]) for r in rows])
    rms = np.array([float(r["rms"]) for r in rows])
    # The full NIST run (benchmarks/RESULTS.md): ΔE2000 median 0.69, max 1.82 (subject 28);
    # RMS median 0.0058, max 0.0086. These five: the same fits.
    assert dE.max() < 2.0 and np.median(dE) < 1.2 and rms.max() < 0.01
    for r in rows:
        for p in bp.PARAMS:
            lo, hi = bp.RANGES[p]
            assert lo <= float(r[p]) <= hi
    assert (out / "five_fit.png").stat().st_size > 20_000
    assert not list(out.glob(".*"))  # no temporary file left


@pytest.mark.slow
def test_synthetic_spectra_recover_their_parameters(fitted):
    """Spectra made by the model itself (on the NIST wavelengths; the fit uses 400-700 nm)
    give back the parameters: measured worst error 0.098 of the range for the eumelanin
    share at melanin 0.01 (weakly seen there; 0.018 and 0.011 for the other two), 4.4 %
    relative for the log-scaled ones (scattering of the second). Noise-free spectra leave
    the weak prior on z to set the last few per cent (fitting 380-780 nm they were 0.03 and
    1.2 %: the 380-400 nm readings see the eumelanin share best)."""
    truth = [bp.DEFAULT, bp.Skin(0.2, 0.6, 0.05, 0.8, 0.06, 1.5),
             bp.Skin(0.01, 0.9, 0.005, 0.4, 0.02, 4.0)]
    wl = np.arange(382.0, 780.0, 3.0)
    with jax.enable_x64(True):
        c = bp.chromophores(wl, formats.haemoglobin_table())
        R = np.stack([np.asarray(bp.reflectance(c, bp.Skin(*map(np.float64, t))))
                      for t in truth])
    r = skin.fit(["a", "b", "c"], wl, R)
    for k, t in enumerate(truth):
        for p in bp.PARAMS:
            got, want = r.params[p][k], getattr(t, p)
            if p in skin.LOG_PARAMS:
                assert got == pytest.approx(want, rel=0.06), (k, p)
            else:
                lo, hi = bp.RANGES[p]
                assert abs(got - want) < (0.12 if p == "eumelanin" else 0.06) * (hi - lo), \
                    (k, p)
    assert r.rms.max() < 2e-4 and r.dE2000.max() < 0.05


@pytest.mark.slow
def test_linearised_uncertainty_against_repeated_noisy_fits(fitted):
    """The `_sd` columns (σ² (JᵀJ)⁻¹) against the spread of 40 fits to the same synthetic
    skin with Gaussian noise σ = 0.003 added: measured ratio (spread / median sd) 0.89–1.03
    per parameter; the spread of an SD from 40 samples is ±11 %, so [0.7, 1.35] (3σ)."""
    truth = bp.Skin(0.1, 0.5, 0.03, 0.6, 0.05, 2.0)
    wl = np.arange(382.0, 780.0, 3.0)
    with jax.enable_x64(True):
        c = bp.chromophores(wl, formats.haemoglobin_table())
        R0 = np.asarray(bp.reflectance(c, bp.Skin(*map(np.float64, truth))))
    R = R0 + np.random.default_rng(1).normal(0.0, 0.003, (40, len(wl)))
    r = skin.fit([f"n{i}" for i in range(40)], wl, R)
    for p in bp.PARAMS:
        ratio = np.std(r.params[p]) / np.median(r.sd[p])
        assert 0.7 < ratio < 1.35, (p, ratio)
    assert np.all(r.corr_melanin_epidermis < -0.5)  # the product is what is seen


@pytest.mark.slow
def test_fixed_parameters_are_held(fitted):
    """`--fix`: a parameter held at its true value stays there exactly and the others are
    still recovered (one more compiled program: the free set is static)."""
    truth = bp.Skin(0.15, 0.5, 0.03, 0.7, 0.08, 2.0)
    wl = np.arange(382.0, 780.0, 3.0)
    with jax.enable_x64(True):
        c = bp.chromophores(wl, formats.haemoglobin_table())
        R = np.asarray(bp.reflectance(c, bp.Skin(*map(np.float64, truth))))[None]
    r = skin.fit(["a"], wl, R, fixed={"epidermis_mm": 0.08})
    assert r.params["epidermis_mm"][0] == pytest.approx(0.08, rel=1e-9)
    assert r.sd["epidermis_mm"][0] == 0 and r.sd["melanin"][0] > 0
    for p in ("melanin", "haemoglobin", "scattering"):
        assert r.params[p][0] == pytest.approx(getattr(truth, p), rel=0.03), p
    assert r.dE2000[0] < 0.05


def test_delta_e2000_against_colour_science_sd_to_xyz():
    """`delta_e2000` (XYZ by the grid's weights) against colour-science's own spectral path
    (SpectralDistribution, interpolated to 5 nm, `sd_to_XYZ`, `XYZ_to_Lab`, `delta_E`):
    measured agreement 1.8e-15 ΔE."""
    import colour

    names, wl, R = formats.read_spectra(NIST)
    a, b = R[0], R[60]
    got = skin.delta_e2000(wl, a, b)
    shape = colour.SpectralShape(380, 780, 5)
    grid = np.arange(380.0, 781.0, 5.0)
    illuminant = colour.SDS_ILLUMINANTS["D65"]
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]

    def lab(r):
        sd = colour.SpectralDistribution(np.interp(grid, wl, r), grid)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            XYZ = colour.sd_to_XYZ(sd.align(shape), cmfs, illuminant) / 100
            white = colour.sd_to_XYZ(colour.SpectralDistribution(np.ones_like(grid), grid),
                                     cmfs, illuminant) / 100
        return colour.XYZ_to_Lab(XYZ, colour.XYZ_to_xy(white))

    want = colour.delta_E(lab(a), lab(b), method="CIE 2000")
    assert 5 < want < 40  # two different skins
    assert got == pytest.approx(want, abs=2e-14)


def test_transform_round_trip_and_bounds():
    z = skin.to_z(bp.DEFAULT)
    back = skin.from_z(z)
    for p, v in zip(bp.PARAMS, back, strict=True):
        assert float(v) == pytest.approx(getattr(bp.DEFAULT, p), rel=1e-5)
    far = skin.from_z(np.array([[-40.0] * 6, [40.0] * 6]))
    for p, v in zip(bp.PARAMS, far, strict=True):
        lo, hi = bp.RANGES[p]
        assert float(v[0]) == pytest.approx(lo, rel=1e-6, abs=1e-12)
        assert float(v[1]) == pytest.approx(hi, rel=1e-6)


# --- Bad inputs: one line, exit 2, nothing written.

def _spectra_file(tmp_path, text, name="s.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _good_rows(lo=380, hi=780, step=10, value="0.4"):
    return "".join(f"{w},{value}\n" for w in range(lo, hi + 1, step))


BAD = [
    ("missing", None, [], "no such file"),
    ("decimal comma", 'wavelength_nm,a\n400,"0,4"\n', [], "decimal point"),
    # percent is guessed from the median (45 is read as 0.45); above 1 with a median of
    # fractions, the flag is named
    ("percent among fractions", "wavelength_nm,a,b\n"
     + "".join(f"{w},0.4,{45 if w == 500 else 0.4}\n" for w in range(380, 790, 10)), [],
     "column 'b': reflectance must be in [0, 1] (use --percent for 0-100), got 45"),
    ("percent above 100", "wavelength_nm,a\n" + _good_rows(value="145"), [],
     "reflectance must be in [0, 100], got 145"),
    ("negative", "wavelength_nm,a\n" + _good_rows(value="-0.1"), [],
     "must be in [0, 1] (below the -0.005 read as noise: reflectances cannot be negative), "
     "got -0.1"),
    # the column named as the header spells it (it said 'wavelength' for wavelength_nm)
    ("not increasing", "wavelength_nm,a\n500,0.4\n490,0.4\n" + _good_rows(), [],
     "column 'wavelength_nm': wavelengths must increase (or all decrease)"),
    ("too short", "wavelength_nm,a\n" + _good_rows(450, 650), [], "at least 400-700 nm"),
    ("no spectra", "wavelength_nm\n" + "".join(f"{w}\n" for w in range(380, 790, 10)), [],
     "no spectra"),
    ("no header", "400,0.4\n500,0.5\n", [], "no header row"),
    # an empty cell is a missing reading; here no spectrum is left covering 400-700 nm
    ("empty cell", "wavelength_nm,a,b\n400,0.4,\n500,0.4,0.3\n", [],
     "no spectrum covers it with readings"),
    ("nan", "wavelength_nm,a\n400,nan\n" + _good_rows(), [], "finite"),
    ("fix unknown", "wavelength_nm,a\n" + _good_rows(), ["--fix", "melanine=0.1"],
     "--fix expects name=value"),
    ("fix out of range", "wavelength_nm,a\n" + _good_rows(), ["--fix", "melanin=0.9"],
     "expected a number in [0.005, 0.5]"),
    ("fix twice", "wavelength_nm,a\n" + _good_rows(), ["--fix", "melanin=0.1", "--fix",
                                                       "melanin=0.2"],
     "--fix melanin given twice (0.1 and 0.2); give it once"),
    ("starts 0", "wavelength_nm,a\n" + _good_rows(), ["--starts", "0"], "--starts"),
]


@pytest.mark.parametrize("label,text,extra,message", BAD, ids=[b[0] for b in BAD])
def test_bad_inputs(tmp_path, capsys, label, text, extra, message):
    src = tmp_path / "absent.csv" if text is None else _spectra_file(tmp_path, text)
    out = tmp_path / "out"
    with pytest.raises(SystemExit) if label == "starts 0" else _nothing() as caught:
        code = main(["fit-skin", str(src), "-o", str(out), *extra])
    if label == "starts 0":
        code = caught.value.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("jaxskin: error:") and message in err[0], err[0]
    assert "Traceback" not in err[0]
    assert not out.exists() or not any(out.iterdir())


def test_output_folder_that_is_a_file(tmp_path, capsys):
    src = _spectra_file(tmp_path, "wavelength_nm,a\n" + _good_rows())
    target = tmp_path / "afile"
    target.write_text("x")
    assert main(["fit-skin", str(src), "-o", str(target)]) == 2
    assert "expected a folder" in capsys.readouterr().err


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_fits_at_the_ends_of_the_range_or_not_converged_are_named():
    """`fit-skin` said nothing of rows with converged=false or a parameter pinned at its
    range's end (the NIST file: melanin at 0.5 for two subjects, scattering at 6 for
    three); now a warning line each, naming up to five spectra. The fractions eumelanin and
    oxygenation end at 0 or 1 naturally, and fixed parameters are not fitted: no line."""
    from jaxskin import biophysical as bp
    from jaxskin.fitting.skin import SkinFit, fit_warnings

    m = 7
    params = {p: np.full(m, getattr(bp.DEFAULT, p), np.float64) for p in bp.PARAMS}
    params["melanin"][[1, 2]] = 0.5 * (1 - 1e-4)  # at the top (log scale, within 0.5 %)
    params["scattering"][3] = 0.5  # at the bottom
    params["haemoglobin"][4] = 0.1  # fixed below: no line
    params["eumelanin"][:] = 0.0  # a natural end
    names = [f"s{i}" for i in range(m)]
    converged = np.ones(m, bool)
    converged[[0, 6]] = False
    zeros = np.zeros(m)
    result = SkinFit(names, np.zeros(3), np.zeros((m, 3)), np.zeros((m, 3)), params, zeros,
                     zeros, converged, zeros, {}, zeros)
    assert fit_warnings(result, {"haemoglobin": 0.1}) == [
        "2 of 7 spectra did not converge (s0, s6): their rows say converged=false; more "
        "--starts may help",
        "melanin ends at the upper end of its range (0.5, within 0.5 % of the range's log) "
        "for 2 spectra (s1 = 0.5, s2 = 0.5): the best fit may lie outside the model's range; "
        "check their rms and dE2000",
        "scattering ends at the lower end of its range (0.5, within 0.5 % of the range's "
        "log) for 1 spectrum (s3 = 0.5): the best fit may lie outside the model's range; "
        "check their rms and dE2000"]
    params["melanin"][:] = 0.2
    assert len(fit_warnings(result, {"haemoglobin": 0.1})) == 2
    converged[:] = True
    params["scattering"][:] = 2.0
    assert fit_warnings(result) == ["haemoglobin ends at the upper end of its range (0.1, "
                                    "within 0.5 % of the range's log) for 1 spectrum (s4 = "
                                    "0.1): the best fit may lie outside the model's range; "
                                    "check their rms and dE2000"]


def test_dark_noise_below_zero_reads_as_zero_as_calibrate_does(tmp_path):
    """fit-skin does not refuse a spectrum with a reading of -0.001 ("set it to 0 in the
    file"), as calibrate reads noise down to -0.005 as 0: the same rule, a note."""
    rows = "".join(f"{w},{-0.001 if w == 380 else -0.004 if w == 390 else 0.4},0.3\n"
                   for w in range(380, 790, 10))
    notes = []
    names, wl, R = formats.read_spectra(_spectra_file(tmp_path, "wavelength_nm,a,b\n" + rows),
                                        notes=notes)
    assert R[0, :3].tolist() == [0.0, 0.0, 0.4] and np.all(R[1] == 0.3)
    assert notes == [f"{tmp_path / 's.csv'}: spectrum 'a': 2 readings below 0 (down to "
                     "-0.004, within the 0.005 of noise) read as 0"], notes
    pc = formats.read_spectra(_spectra_file(tmp_path, "wavelength_nm,a\n" + "".join(
        f"{w},{-0.3 if w == 380 else 40}\n" for w in range(380, 790, 10)), "pc.csv"),
        percent=True)[2]
    assert pc[0, 0] == 0.0 and pc[0, 1] == pytest.approx(0.4)


@pytest.mark.parametrize("name", ["Wellenlänge (nm)", "Wavelength nm", "wavelength/nm",
                                  "λ (nm)", "Longueur d'onde (nm)"])
def test_spectra_read_the_wavelength_column_by_its_other_names(tmp_path, name):
    """fit-skin knew five spellings of the wavelength column; it reads what calibrate
    reads (nm only: a µm header is not one of its spectra's)."""
    names, wl, R = formats.read_spectra(_spectra_file(tmp_path, f"{name};a\n" + "".join(
        f"{w};0,4\n" for w in range(380, 790, 10))))
    assert names == ["a"] and wl[0] == 380 and wl[-1] == 780 and np.all(R == 0.4)


def test_spectra_rows_repeated_exactly_are_read_once(tmp_path):
    rows = [f"{w},0.4,0.3" for w in range(380, 790, 10)]
    text = "wavelength_nm,a,b\n" + "\n".join(rows[:5] + rows[4:5] * 2 + rows[5:]) + "\n"
    notes = []
    names, wl, R = formats.read_spectra(_spectra_file(tmp_path, text), notes=notes)
    assert wl.tolist() == list(range(380, 790, 10)) and R.shape == (2, 41)
    assert notes == [f"{tmp_path / 's.csv'}: lines 7 (= 6), 8 (= 7) repeat the row before: "
                     "read once"], notes


def test_a_spectrum_whose_header_says_percent_is_read_as_percent_and_named_without_it(
        tmp_path):
    """`Forearm A (%)` drops its unit from the name (fit.csv, the report) and is read as
    percent by its header, not by the median's guess, as calibrate reads it."""
    rows = "".join(f"{w};37,5;0,2\n" for w in range(380, 790, 10))
    notes = []
    names, wl, R = formats.read_spectra(_spectra_file(
        tmp_path, "Wavelength (nm);Forearm A (%);Cheek B\n" + rows), notes=notes)
    assert names == ["Forearm A", "Cheek B"]
    assert np.allclose(R[0], 0.375) and np.allclose(R[1], 0.2)  # only the one that says %
    assert f"{tmp_path / 's.csv'}: column 'Forearm A (%)' says %: read as percent (/ 100)" \
        in notes, notes


def test_a_number_with_percent_in_a_name_is_not_a_unit(tmp_path):
    """`Foundation 30%` is not the spectrum `Foundation 30` in percent, its 0.3-0.5
    divided to a near-black 0.003 and fitted with exit 0: a number's % is part of the
    name; a column that says % over readings all at most 1 is refused."""
    from jaxskin.io import InputError

    rows = "".join(f"{w},0.4,0.3\n" for w in range(380, 790, 10))
    names, wl, R = formats.read_spectra(_spectra_file(
        tmp_path, "wavelength_nm,Foundation 30%,Forearm\n" + rows))
    assert names == ["Foundation 30%", "Forearm"] and np.allclose(R[0], 0.4)
    with pytest.raises(InputError, match=r"s.csv:1: column 'Cheek \(%\)': says %, but every "
                                         r"reading is at most 1"):
        formats.read_spectra(_spectra_file(tmp_path, "wavelength_nm,Cheek (%),Forearm\n" +
                                           rows))
    with pytest.raises(InputError, match=r"column '%': a spectrum's name is its unit alone"):
        formats.read_spectra(_spectra_file(tmp_path, "wavelength_nm,%,Forearm\n" +
                                           rows.replace(",0.4,", ",40,")))


def test_spectra_in_micrometres_are_named_as_such(tmp_path):
    """`wavelength_um` is a name fit-skin knows, in a unit it does not take: it says so,
    not "not a name this reader knows"."""
    from jaxskin.io import InputError

    path = _spectra_file(tmp_path, "wavelength_um,a\n0.4,0.3\n0.41,0.3\n")
    with pytest.raises(InputError, match=r"line 1 begins with 'wavelength_um': wavelengths in "
                                         r"um; this reader takes nm: give them in nm, as "
                                         r"wavelength_nm\)$"):
        formats.read_spectra(path)


@pytest.mark.parametrize("name, cell", [
    ("subject_12", "subject_12"),
    ("a,b", '"a,b"'),
    ('say "hi"', '"say ""hi"""'),
    ("=cmd|' /C calc'!A0", "'=cmd|' /C calc'!A0"),
    ("+1", "'+1"), ("-x", "'-x"), ("@sum", "'@sum"),
    ("=a,b", "\"'=a,b\""),
])
def test_a_spectrums_name_is_a_safe_csv_cell(name, cell):
    """A spectrum named `=cmd|' /C calc'!A0` must not go into `*_fit.csv` as it is, where a
    spreadsheet may run it as a formula, and an inner quote is doubled. A CSV reader reads
    the name back, led by `'` where it started like a formula."""
    import io

    from jaxskin.fitting._skin_files import _cell

    assert _cell(name) == cell
    formula = name[:1] in "=+-@"
    assert next(csv.reader(io.StringIO(cell + ",1\n"))) == [("'" if formula else "") + name, "1"]
