"""The measurement CSV reader: every accepted form, and one precise line for each bad input."""

import os

import numpy as np
import pytest

from jaxskin.fitting.measurements import read_measurement
from jaxskin.io import InputError, data_dir

GOOD = """# name: test_foundation
wavelength_nm,R_0.05mm,R_0.15mm,R_inf,R_g
400,0.30,0.40,0.45,0.04
410,0.31,0.41,0.46,0.04
420,0.32,0.42,0.47,0.04
"""


def write(tmp_path, text, name="m.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_thin_layers_sorted_by_thickness(tmp_path):
    text = GOOD.replace("R_0.05mm,R_0.15mm", "R_0.15mm,R_0.05mm")
    m = read_measurement(write(tmp_path, text))
    assert m.name == "test_foundation"
    np.testing.assert_array_equal(m.thickness_mm, [0.05, 0.15])
    np.testing.assert_array_equal(m.R[0], [0.40, 0.41, 0.42])  # the 0.05 mm column, moved first
    np.testing.assert_array_equal(m.wavelength_nm, [400, 410, 420])


def test_bare_r_thickness_from_comment_or_flag(tmp_path):
    text = "# thickness_mm: 0.2\nwavelength_nm,R,R_inf,R_g\n400,0.3,0.4,0.04\n410,0.3,0.4,0.04\n"
    path = write(tmp_path, text, "bare.csv")
    assert read_measurement(path).thickness_mm.tolist() == [0.2]
    assert read_measurement(path, thickness_mm=0.1).thickness_mm.tolist() == [0.1]
    assert read_measurement(path).name == "bare"
    assert read_measurement(path).notes == ()
    assert read_measurement(path, thickness_mm=0.2).notes == ()


def test_a_thickness_comment_that_is_not_used_gets_a_note(tmp_path):
    """'# thickness_mm:' over named columns only (each names its own thickness), or under
    --thickness: a note naming the line, not silence."""
    path = write(tmp_path, "# thickness_mm: 0.2\n" + GOOD.replace("# name: test_foundation\n",
                                                                  ""), "named.csv")
    m = read_measurement(path)
    assert m.thickness_mm.tolist() == [0.05, 0.15]
    assert m.notes == (f"{path}:1: '# thickness_mm: 0.2' is not used: no bare R (or E) "
                       "column; the R_<X>mm columns name their own thicknesses",)
    text = "# thickness_mm: 0.2\nwavelength_nm,R,R_inf,R_g\n400,0.3,0.4,0.04\n410,0.3,0.4,0.04\n"
    path = write(tmp_path, text, "bare.csv")
    assert read_measurement(path, thickness_mm=0.1).notes == (
        f"{path}:1: '# thickness_mm: 0.2' is overridden by --thickness 0.1",)


@pytest.mark.parametrize("key, first, second", [("thickness_mm", "0.2", "0.02"),
                                                ("name", "blush_a", "blush_b")])
def test_a_key_given_twice_with_two_values_is_an_error(tmp_path, key, first, second):
    """A '# thickness_mm:' put above an instrument's own (or a second '# name:') once went
    unnoticed: the first was used. Now the second line is named; the same value twice and
    a repeated free-form comment key are fine."""
    body = "wavelength_nm,R,R_inf,R_g\n400,0.3,0.4,0.04\n410,0.3,0.4,0.04\n"
    path = write(tmp_path, f"# {key}: {first}\n# note: a\n# {key}: {second}\n# note: b\n"
                 + ("# thickness_mm: 0.1\n" if key == "name" else "") + body)
    with pytest.raises(InputError) as info:
        read_measurement(path)
    assert str(info.value) == (f"{path}:3: '# {key}:' again, with another value than on "
                               f"line 1 ({first!r}); keep one")
    same = write(tmp_path, f"# {key}: {first}\n# {key}: {first}\n"
                 + ("# thickness_mm: 0.1\n" if key == "name" else "") + body, "same.csv")
    assert read_measurement(same).notes == ()


def test_percent_and_radiance(tmp_path):
    pct = write(
        tmp_path,
        GOOD.replace("0.30,0.40,0.45,0.04", "30,40,45,4")
        .replace("0.31,0.41,0.46", "31,41,46")
        .replace("0.32,0.42,0.47", "32,42,47")
        .replace(",0.04", ",4"),
        "pct.csv",
    )
    m = read_measurement(pct, percent=True)
    np.testing.assert_allclose(m.R_inf, [0.45, 0.46, 0.47])
    rad = write(
        tmp_path,
        "wavelength_nm,E_R_0.1mm,E_inf,E_g,E_white\n400,1.0,2.0,0.2,4.0\n410,1.5,3.0,0.3,6.0\n",
        "rad.csv",
    )
    m = read_measurement(rad)
    np.testing.assert_allclose(m.R[0], [0.25, 0.25])
    np.testing.assert_allclose(m.R_inf, [0.5, 0.5])
    np.testing.assert_allclose(m.R_g, [0.05, 0.05])


def _bad(text_from_good):
    return text_from_good(GOOD)


BAD = [
    # (what, how to break GOOD, line, column, words in the message)
    (
        "missing R_inf",
        lambda t: (
            t.replace(",R_inf", "").replace(",0.45", "").replace(",0.46", "").replace(",0.47", "")
        ),
        2,
        None,
        "missing column R_inf",
    ),
    ("unknown column", lambda t: t.replace("R_g", "R_ground"), 2, "R_ground", "unknown column"),
    ("non-numeric cell", lambda t: t.replace("0.41", "abc"), 4, "R_0.15mm", "expected a number"),
    ("NaN", lambda t: t.replace("0.41", "nan"), 4, "R_0.15mm", "finite"),
    ("above 1", lambda t: t.replace("0.46", "46"), 4, "R_inf", "--percent"),
    ("negative", lambda t: t.replace("0.04\n410", "-0.01\n410"), 3, "R_g", "[0, 1]"),
    ("wavelength order", lambda t: t.replace("420,", "405,"), 5, "wavelength_nm", "increase"),
    (
        "ragged row",
        lambda t: t.replace("0.41,0.46", "0.41"),
        4,
        None,
        "4 cells where the header has 5",
    ),
    ("zero thickness", lambda t: t.replace("R_0.05mm", "R_0mm"), 2, "R_0mm", "positive"),
    ("negative thickness", lambda t: t.replace("R_0.05mm", "R_-0.1mm"), 2, "R_-0.1mm", "positive"),
    (
        "R_g equal to R_inf",
        lambda t: (
            t.replace("0.45,0.04", "0.45,0.45")
            .replace("0.46,0.04", "0.46,0.46")
            .replace("0.47,0.04", "0.47,0.47")
        ),
        2,
        "R_g",
        "R_g equals R_inf",
    ),
    ("duplicate column", lambda t: t.replace("R_0.15mm", "R_0.05mm"), 2, "R_0.05mm", "twice"),
    ("no wavelength column", lambda t: t.replace("wavelength_nm", "frequency_hz"), None, None,
     "no header row"),
    # A header needs a reading column (R… or E…) too; without the rule this row was the
    # header and the error 'unknown column'.
    ("no reading column", lambda t: t.replace(",R_", ",r_"), 2, None,
     "no column is a cosmetic's reading ('r_0.05mm', 'r_0.15mm', ...): calibrate reads "
     "R_<X>mm, R_inf, R_g or E_... columns, with a capital R or E"),
    ("bare R without thickness", lambda t: t.replace("R_0.15mm", "R"), 2, "R", "thickness"),
    (
        "bad thickness comment",
        lambda t: "# thickness_mm: thin\n" + t,
        1,
        "key 'thickness_mm'",  # a `# key:` line, not a column
        "positive",
    ),
    ("no data", lambda t: t.split("400")[0], 2, None, "needs at least 2 data rows"),
    ("radiance without white", lambda t: t.replace("R_inf", "E_inf"), 2, "E_inf", "E_white"),
    # an instrument's extra column is named with the two ways to skip it, not a bare
    # 'unknown column' with no way past it
    ("extra column", lambda t: t.replace("R_g\n", "R_g,SD_0.05mm\n").replace("0.04\n",
                                                                             "0.04,0.01\n"),
     2, "SD_0.05mm", "skip other columns with '# ignore: NAME' or --ignore"),
    ("thickness without a number", lambda t: t.replace("R_0.05mm", "RSD_0.05mm"), 2,
     "RSD_0.05mm", "unknown column"),
    ("thickness without a unit", lambda t: t.replace("R_0.05mm", "R_0.05"), 2, "R_0.05",
     "unknown column"),
    ("zero thickness in µm", lambda t: t.replace("R_0.05mm", "R_0um"), 2, "R_0um", "positive"),
    ("an ignore line naming no column", lambda t: "# ignore: SD\n" + t, 1, None,
     "'# ignore:' names 'SD', which is no column of the header"),
    ("ignoring the wavelengths", lambda t: "# ignore: wavelength_nm\n" + t, 3,
     "wavelength_nm", "the first column cannot be ignored"),
    ("two ignore lines", lambda t: "# ignore: R_g\n# ignore: R_inf\n" + t, 2, None,
     "'# ignore:' again"),
]


@pytest.mark.parametrize("what, breaker, line, column, words", BAD, ids=[b[0] for b in BAD])
def test_bad_input_names_file_line_and_column(tmp_path, what, breaker, line, column, words):
    path = write(tmp_path, breaker(GOOD), "bad.csv")
    with pytest.raises(InputError) as info:
        read_measurement(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}:{line}:" if line else f"{path}: "), message
    if column is not None:
        named = column if column.startswith("key ") else f"column '{column}'"
        assert named in message, message
    assert words in message, message


def test_missing_file_and_bad_flag(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_measurement(tmp_path / "nope.csv")
    with pytest.raises(InputError, match="--thickness"):
        read_measurement(write(tmp_path, GOOD), thickness_mm=-1.0)


# ------------------------------------------------------------------ as instruments write them

WL = [400, 410, 420]
TABLE = [[0.30, 0.40, 0.45, 0.04], [0.31, 0.41, 0.46, 0.04], [0.32, 0.42, 0.47, 0.04]]


def _export(header, sep=",", preamble="", scale_wl=1.0, scale_r=1.0, quote=False, eol="\n",
            trailing=""):
    q = (lambda s: f'"{s}"') if quote else (lambda s: s)
    lines = [sep.join(q(h) for h in header) + trailing]
    for w, r in zip(WL, TABLE, strict=True):
        lines.append(sep.join([f"{w * scale_wl:g}", *(f"{v * scale_r:g}" for v in r)]) + trailing)
    return preamble + eol.join(lines) + eol


NAMES = ["R_0.05mm", "R_0.15mm", "R_inf", "R_g"]
STYLES = {
    # ASD ViewSpecPro-style text export: free-text preamble, `key: value` lines, tabs.
    "tab, free-text preamble": _export(
        ["Wavelength", *NAMES], "\t",
        "Spectrum file: foundation_00001.asd\nInstrument: FieldSpec 4 Hi-Res NG\n"
        "Integration time: 136 ms\nForeoptic: contact probe\n\n"),
    # European spreadsheet export: semicolons, every field quoted, CRLF, a UTF-8 BOM.
    "semicolon, quoted, CRLF, BOM": "\ufeff" + _export(["wavelength_nm", *NAMES], ";",
                                                       quote=True, eol="\r\n"),
    # `key,value` metadata rows before the header (Ocean/Avantes-style CSV), a trailing comma.
    "key,value preamble, trailing comma": _export(
        ["Wavelength (nm)", *NAMES], ",",
        "Date,2026-11-29\nOperator,lab 3\nIntegration Time (ms),100\n", trailing=","),
    "µm with the unit in the header": _export(["wavelength [µm]", *NAMES], scale_wl=1e-3),
    # The wavelength column named by its unit alone.
    "nm as the wavelength column": _export(["nm", *NAMES]),
    # A preamble row that starts with the wavelength's name but has no reading column is not
    # the header (it was: 'unknown column 400-420').
    "a preamble row starting 'Wavelength'": _export(["Wavelength (nm)", *NAMES], ",",
                                                    "Wavelength,400-420\nPoints,3\n"),
    # What spreadsheets in other languages and the SI style write (not "no header row").
    **{f"header {name!r}": _export([name, *NAMES], ";") for name in (
        "Wellenlänge (nm)", "Wellenlaenge [nm]", "Wavelength nm", "wavelength/nm",
        "Longueur d onde (nm)", "Longueur d'onde (nm)", "Longitud de onda (nm)",
        "Lunghezza d'onda (nm)", "Comprimento de onda (nm)", "Golflengte (nm)")},
}


@pytest.mark.parametrize("style", STYLES)
def test_instrument_exports_read_like_the_plain_format(tmp_path, style):
    plain = read_measurement(write(tmp_path, _export(["wavelength_nm", *NAMES]), "plain.csv"))
    path = tmp_path / "export.csv"
    path.write_bytes(STYLES[style].encode("utf-8"))
    m = read_measurement(path)
    np.testing.assert_allclose(m.wavelength_nm, plain.wavelength_nm, rtol=1e-12)
    for a in ("R", "R_inf", "R_g", "thickness_mm"):
        np.testing.assert_array_equal(getattr(m, a), getattr(plain, a))
    assert m.notes == ()  # nothing inferred: the header said the unit


def test_no_header_names_what_the_first_row_begins_with(tmp_path):
    """A bare "no header row" leaves the user to guess which cell was not understood; the
    row quoted is the one above the data, not the preamble's first."""
    pre = write(tmp_path, "Instrument: CM-700d\nDate: 2026\nWavelenght (nm);R_0,05mm;R_inf;"
                "R_g\n400;0,3;0,4;0,04\n410;0,3;0,4;0,04\n", "pre.csv")
    with pytest.raises(InputError, match=r"\(line 3 begins with 'Wavelenght \(nm\)': not a "):
        read_measurement(pre)
    path = write(tmp_path, "Golden;R_0,05mm;R_inf;R_g\n400;0,3;0,4;0,04\n", "g.csv")
    with pytest.raises(InputError, match=r"g.csv: no header row; .* after any preamble \(line "
                                         r"1 begins with 'Golden': not a name this reader knows "
                                         r"for the first column: name it wavelength_nm\)$"):
        read_measurement(path)


def test_micrometres_and_percent_are_detected_with_a_note(tmp_path):
    plain = read_measurement(write(tmp_path, _export(["wavelength_nm", *NAMES]), "plain.csv"))
    m = read_measurement(write(tmp_path, _export(["wavelength", *NAMES], scale_wl=1e-3,
                                                 scale_r=100.0)))
    np.testing.assert_allclose(m.wavelength_nm, plain.wavelength_nm, rtol=1e-12)
    np.testing.assert_allclose(m.R_inf, plain.R_inf, rtol=1e-12)
    assert len(m.notes) == 2
    assert "read as µm" in m.notes[0] and "read as percent" in m.notes[1]
    # --percent forces it; a fraction file is left alone.
    assert read_measurement(write(tmp_path, _export(["wavelength_nm", *NAMES]))).notes == ()


def test_dark_percent_data_is_not_guessed(tmp_path):
    """Median 1.2 %: as fractions it would be > 1 in places; ambiguous, so an error that
    points at --percent rather than a guess."""
    text = "wavelength_nm,R_0.1mm,R_inf,R_g\n400,1.0,1.2,4.0\n410,1.1,1.3,0.5\n420,0.9,1.2,0.5\n"
    with pytest.raises(InputError, match="use --percent"):
        read_measurement(write(tmp_path, text))
    m = read_measurement(write(tmp_path, text), percent=True)
    np.testing.assert_allclose(m.R_inf, [0.012, 0.013, 0.012])


def test_percent_on_fractions_is_refused(tmp_path):
    """`--percent` given to data already in 0-1 (an easy slip: the fit would run on
    reflectances 100x too dark; a warning alone still lets calibrate write a material with
    12 of 81 bands identifiable): calibrate's and fit-skin's readers refuse it, naming the
    file; percent data with the flag is read without a word."""
    import warnings

    from jaxskin.formats import read_spectra

    src = data_dir() / "measurements" / "lipstick_red.csv"
    (tmp_path / "m.csv").write_text(src.read_text())
    with pytest.raises(InputError, match=r"m\.csv: --percent, but every reflectance is at "
                       r"most 1 \(median 0\.\d+\): these are fractions \(0-1\); leave"):
        read_measurement(tmp_path / "m.csv", percent=True)
    (tmp_path / "s.csv").write_text("wavelength_nm,a\n400,0.2\n500,0.3\n600,0.4\n")
    with pytest.raises(InputError, match=r"s\.csv: --percent, but every reflectance"):
        read_spectra(tmp_path / "s.csv", percent=True)
    (tmp_path / "p.csv").write_text("wavelength_nm,a\n400,20\n500,30\n600,40\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_spectra(tmp_path / "p.csv", percent=True)


def test_a_file_name_that_is_not_a_name_is_made_safe_with_a_note(tmp_path):
    """`Lipstick Red (batch 5).csv` without '# name:' is neither refused nor a crash: named
    `lipstick_red_batch_5`, and a note says so; a valid stem is kept as it is;
    a derived name that is empty or over the length limit is an error naming the file."""
    text = GOOD.replace("# name: test_foundation\n", "")
    m = read_measurement(write(tmp_path, text, "Lipstick Red (batch 5).csv"))
    assert m.name == "lipstick_red_batch_5"
    assert m.notes == (f"{tmp_path / 'Lipstick Red (batch 5).csv'}: the file name is not a "
                       "material name (letters, digits, '.', '_', '+', '-'): named it "
                       "'lipstick_red_batch_5' (set it with '# name: NAME')",)
    m = read_measurement(write(tmp_path, text, "Foundation_2.csv"))
    assert m.name == "Foundation_2" and m.notes == ()
    # letters of any script are letters ('Crème teint 3' keeps its è, and '日本語 ファンデ'
    # has letters)
    for stem, name in (("Crème teint 3", "crème_teint_3"), ("日本語 ファンデ", "日本語_ファンデ"),
                       ("日本語ファンデ", "日本語ファンデ")):
        assert read_measurement(write(tmp_path, text, f"{stem}.csv")).name == name
    with pytest.raises(InputError) as info:
        read_measurement(write(tmp_path, text, "(((.csv"))
    assert str(info.value) == (f"{tmp_path / '(((.csv'}: the file name '(((.csv' has no letters "
                               "or digits to name the material: add a line '# name: NAME' to "
                               "the file")
    long = write(tmp_path, text, "A b" * 70 + ".csv")
    with pytest.raises(InputError) as info:
        read_measurement(long)
    assert str(info.value).startswith(f"{long}: the material name from the file name is 210 "
                                      "characters, more than 200: add a line '# name: NAME'")


def test_descending_wavelengths_are_read_in_order_and_a_negative_reading_is_named(tmp_path):
    """Some instruments export the long wavelengths first: not refused ("wavelengths must
    increase, got 420 then 410") but read in increasing order with a note. A dark-corrected
    reading of -0.0012 is not told "percent data? use --percent"."""
    lines = GOOD.splitlines()
    flipped = write(tmp_path, "\n".join([*lines[:2], *lines[:1:-1]]) + "\n", "down.csv")
    up, down = read_measurement(write(tmp_path, GOOD, "up.csv")), read_measurement(flipped)
    np.testing.assert_array_equal(down.wavelength_nm, up.wavelength_nm)
    np.testing.assert_array_equal(down.R_inf, up.R_inf)
    assert any("wavelengths descend" in n for n in down.notes)
    with pytest.raises(InputError, match=r"bad.csv:3: column 'R_g': reflectance must be in "
                                         r"\[0, 1\], got -0.012 \(below the -0.005 read as "
                                         r"noise: reflectances cannot be negative\)"):
        read_measurement(write(tmp_path, GOOD.replace("400,0.30,0.40,0.45,0.04",
                                                      "400,0.30,0.40,0.45,-0.012"), "bad.csv"))
    # a black card's dark-corrected noise, -0.0012 and -0.005, is read as 0 with a note,
    # not a refusal of the whole file; in percent the same margin is 0.5
    noisy = read_measurement(write(tmp_path, GOOD.replace("0.04\n410", "-0.0012\n410")
                                   .replace("0.04\n420", "-0.005\n420"), "noisy.csv"))
    np.testing.assert_array_equal(noisy.R_g, [0.0, 0.0, 0.04])
    assert any("column 'R_g': 2 readings below 0 (down to -0.005, within the 0.005 of noise) "
               "read as 0" in n for n in noisy.notes), noisy.notes


@pytest.mark.parametrize("header", [
    "wavelength_nm,R_50um,R_150µm,R inf,R_g",        # micrometres, a space
    "wavelength_nm,R 0.05 mm,R_0.15_mm,R_∞,R_g",     # spaces, underscores, ∞
    "wavelength_nm,R0.05mm,R_0.15mm,R_inf,R_g",      # no separator
    "wavelength_nm,R_0.05mm,R_0.15mm,R∞,Rg",         # R∞, Rg
    "wavelength_nm,R_0.05mm,R_0.15mm,Rinf,R_g",
])
def test_other_spellings_of_the_columns_read_like_the_format(tmp_path, header):
    """`R_3um`, `R 0.05 mm` and the like are not 'unknown column': they are the format's
    columns, thicknesses in mm (50 µm = 0.05 mm)."""
    plain = read_measurement(write(tmp_path, GOOD, "plain.csv"))
    m = read_measurement(write(tmp_path, GOOD.replace(
        "wavelength_nm,R_0.05mm,R_0.15mm,R_inf,R_g", header)))
    np.testing.assert_array_equal(m.thickness_mm, [0.05, 0.15])
    for got, want in ((m.R, plain.R), (m.R_inf, plain.R_inf), (m.R_g, plain.R_g)):
        np.testing.assert_array_equal(got, want)
    rad = write(tmp_path, "wavelength_nm,E 100 um,E_R_inf,E g,E white\n"
                "400,1.0,2.0,0.2,4.0\n410,1.5,3.0,0.3,6.0\n", "rad.csv")
    m = read_measurement(rad)
    np.testing.assert_allclose(m.thickness_mm, [0.1])
    np.testing.assert_allclose(m.R[0], [0.25, 0.25])
    np.testing.assert_allclose(m.R_g, [0.05, 0.05])


def test_ignored_columns_are_not_read_and_are_named(tmp_path):
    """Standard deviations and notes beside the readings: skipped by the file's
    '# ignore:' line (names or patterns) or the caller's patterns, not parsed (text is
    fine), named in a note; the readings are those of the plain file."""
    plain = read_measurement(write(tmp_path, GOOD, "plain.csv"))
    text = ("# name: test_foundation\n# ignore: Notes\n"
            "wavelength_nm,R_0.05mm,SD_0.05mm,R_0.15mm,SD_0.15mm,R_inf,R_g,Notes\n"
            "400,0.30,0.01,0.40,0.02,0.45,0.04,dark room\n"
            "410,0.31,0.01,0.41,0.02,0.46,0.04,\"lamp, warm\"\n"
            "420,0.32,0.01,0.42,0.02,0.47,0.04,-\n")
    path = write(tmp_path, text, "sd.csv")
    with pytest.raises(InputError, match="column 'SD_0.05mm': unknown column"):
        read_measurement(path)
    for ignore in (["SD_*"], "SD_*", ["SD_0.05mm", "SD_0.15mm", "absent"]):
        m = read_measurement(path, ignore=ignore)
        np.testing.assert_array_equal(m.R, plain.R)
        np.testing.assert_array_equal(m.R_inf, plain.R_inf)
        assert m.notes == (f"{path}: ignored columns SD_0.05mm, SD_0.15mm, Notes",)
    m = read_measurement(write(tmp_path, text.replace("# ignore: Notes", "# ignore: SD_*; Notes"),
                               "own.csv"))
    np.testing.assert_array_equal(m.R, plain.R)


def test_fit_skin_reads_percent_spectra_with_a_note(tmp_path):
    """fit-skin and calibrate read percent spectra without --percent alike: both guess,
    from a median above 1.5, and say so."""
    from jaxskin.formats import read_spectra

    (tmp_path / "p.csv").write_text("wavelength_nm,a,b\n400,20,35.5\n500,30,41\n600,40,52\n")
    notes = []
    names, wl, R = read_spectra(tmp_path / "p.csv", percent=None, notes=notes)
    np.testing.assert_allclose(R, [[0.2, 0.3, 0.4], [0.355, 0.41, 0.52]])
    assert notes == [f"{tmp_path / 'p.csv'}: reflectances have a median of 37.8: read as "
                     "percent (/ 100; --percent says so)"]
    (tmp_path / "f.csv").write_text("wavelength_nm,a\n400,0.9\n500,1.4\n600,1.2\n")
    with pytest.raises(InputError, match=r"got 1.4 at 500 nm"):  # median 1.2: not guessed
        read_spectra(tmp_path / "f.csv", percent=None)


def test_spreadsheet_exports_decimal_commas_empty_rows_and_a_footer(tmp_path):
    """European Excel exports: decimal commas where ';' or tabs separate the columns (then
    they cannot be a column break) read as points, with a note; rows of bare delimiters
    (",,,,") skipped like blank lines; a footer line after the data named as one (it was
    "1 cells where the header has 5"). A decimal comma in a comma-separated file stays an
    error (none of the three refuses the whole file)."""
    plain = read_measurement(write(tmp_path, GOOD, "plain.csv"))
    for sep in (";", "\t"):
        head, rows = GOOD.split("R_g\n")
        text = (head.replace(",", sep) + "R_g\n" + rows.replace(",", sep).replace(".", ",")
                + sep * 4 + "\n" + sep * 4 + "\n")
        m = read_measurement(write(tmp_path, text, "eu.csv"))
        for a in ("R", "R_inf", "R_g", "thickness_mm", "wavelength_nm"):
            np.testing.assert_array_equal(getattr(m, a), getattr(plain, a))
        # the file's own first decimal comma quoted (a fixed "18,65" read as if it were)
        assert f"{tmp_path / 'eu.csv'}: numbers with a decimal comma (0,30) read with a " \
            "point (0.30)" in m.notes, m.notes
    assert not any("decimal comma" in n for n in plain.notes)
    empty_rows = read_measurement(write(tmp_path, GOOD + ",,,,\n,,,,\n", "rows.csv"))
    np.testing.assert_array_equal(empty_rows.R, plain.R)
    with pytest.raises(InputError, match=r"foot.csv:6: a row that is not data \('End of "
                                         r"data'\): delete it, or start it with '#'"):
        read_measurement(write(tmp_path, GOOD + "End of data\n", "foot.csv"))
    with pytest.raises(InputError, match=r"column 'R_inf': expected a number with a decimal "
                                         r"point, got '0,45' \(in a comma-separated file"):
        read_measurement(write(tmp_path, GOOD.replace("0.45", '"0,45"'), "c.csv"))
    # decimal commas in a comma-separated file: the cells split at every comma
    commas = ("wavelength_nm,R_0.05mm,R_0.15mm,R_inf,R_g\n400,0,30,0,40,0,45,0,04\n"
              "410,0,31,0,41,0,46,0,05\n")
    with pytest.raises(InputError, match=r"dc.csv:2: 9 cells where the header has 5 \(decimal "
                                         r"commas in a comma-separated file\? 0,54 is then two "
                                         r"cells: export with ';' or tab between cells"):
        read_measurement(write(tmp_path, commas, "dc.csv"))
    with pytest.raises(InputError, match=r"pc.csv:3: column 'R_0.05mm': expected a number, "
                                         r"got '30 %': write percent without the '%' sign"):
        read_measurement(write(tmp_path, GOOD.replace("0.30", "30 %"), "pc.csv"))


@pytest.mark.parametrize("text, line, words", [
    # one row per reading, wavelengths along the first row (an X-Rite style export)
    ("Sample Name,400nm,410nm,420nm,430nm\nR_0.05mm,0.3,0.31,0.32,0.33\n", 1,
     "wavelengths run along this row (400nm, 410nm, ...: one row per reading): the format "
     "has them down the first column"),
    ("# lab 3\nSample;400;410;420;430;440\nR_inf;0.3;0.31;0.32;0.33;0.34\n", 2,
     "wavelengths run along this row"),
    # a sample name before the wavelengths
    ("Sample,wavelength_nm,R_0.05mm,R_0.15mm,R_inf,R_g\nA,400,0.3,0.4,0.45,0.04\n", 1,
     "the wavelength column 'wavelength_nm' is not the first: move it first, or delete the "
     "column before it ('Sample')"),
    # skin spectra (what fit-skin reads), given to calibrate: named as such, not as
    # wavelengths not in nm, of a header 'wavelength_nm'
    ("wavelength_nm,subject_12,subject_44,subject_90\n400,0.21,0.05,0.12\n"
     "410,0.22,0.06,0.13\n", 1,
     "no column is a cosmetic's reading ('subject_12', 'subject_44', ...; calibrate reads "
     "R_<X>mm, R_inf, R_g or E_... columns): skin reflectance spectra, one per column, are "
     "fitted with 'jaxskin fit-skin "),
    # columns that merely start with r or e are no lower-case readings
    ("wavelength_nm,reflectance_arm,e1\n400,0.21,0.05\n410,0.22,0.06\n", 1,
     "no column is a cosmetic's reading ('reflectance_arm', 'e1'; calibrate reads "),
])
def test_other_layouts_are_named(tmp_path, text, line, words):
    """A transposed export or a sample-name column first is named, with its line, not a
    bare "no header row"."""
    with pytest.raises(InputError) as info:
        read_measurement(write(tmp_path, text, "x.csv"))
    assert str(info.value).startswith(f"{tmp_path / 'x.csv'}:{line}: {words}"), str(info.value)


@pytest.mark.parametrize("column, note", [
    ("R_3mm", "column 'R_3mm': a 3 mm film; cosmetic films are 0.1 µm to 1 mm thick, and S, K "
              "scale as 1 / thickness: µm (R_<X>um) meant?"),
    ("R_0.05um", "column 'R_0.05um': a 5e-05 mm film; cosmetic films are 0.1 µm to 1 mm "
                 "thick, and S, K scale as 1 / thickness: mm meant?"),
])
def test_a_film_thickness_far_from_a_cosmetics_is_named(tmp_path, column, note):
    """R_3mm written for R_3um fits as well as the right unit, with S and K 1000× too
    small: a note names it."""
    m = read_measurement(write(tmp_path, GOOD.replace("R_0.05mm", column)))
    assert any(note in n for n in m.notes), m.notes
    assert not any("film" in n for n in read_measurement(write(tmp_path, GOOD, "g.csv")).notes)


def test_a_name_line_that_is_no_name_suggests_one(tmp_path):
    with pytest.raises(InputError, match=r"m.csv:1: name 'Rouge n°12' must be letters, .*"
                                         r"e.g. '# name: rouge_n_12'"):
        read_measurement(write(tmp_path, GOOD.replace("test_foundation", "Rouge n°12")))


def test_a_white_standards_certified_reflectance_scales_radiance(tmp_path):
    """Radiance divided by E_white as if the standard reflected 1 puts every reflectance
    2 % high and K/S up to 9 % off for a tile certified at 0.98. `# white_reflectance:`
    or `white_reflectance=` (the CLI's --white-reflectance, which wins, with a note) scale
    R = E / E_white by it."""
    rad = ("wavelength_nm,E_0.1mm,E_inf,E_g,E_white\n"
           "400,1.0,2.0,0.2,4.0\n410,1.5,3.0,0.3,6.0\n")
    plain = read_measurement(write(tmp_path, rad, "plain.csv"))
    np.testing.assert_allclose(plain.R[0], [0.25, 0.25], rtol=1e-15)
    tile = read_measurement(write(tmp_path, "# white_reflectance: 0.98\n" + rad, "tile.csv"))
    np.testing.assert_allclose(tile.R[0], [0.245, 0.245], rtol=1e-15)
    np.testing.assert_allclose(tile.R_inf, [0.49, 0.49], rtol=1e-15)
    flag = read_measurement(tmp_path / "tile.csv", white_reflectance=0.9)
    np.testing.assert_allclose(flag.R_g, [0.045, 0.045], rtol=1e-15)
    assert any("'# white_reflectance: 0.98' is overridden by --white-reflectance 0.9" in n
               for n in flag.notes), flag.notes
    with pytest.raises(InputError, match=r"bad.csv:1: key 'white_reflectance': expected a "
                                         r"reflectance in \(0, 1\], got '98'"):
        read_measurement(write(tmp_path, "# white_reflectance: 98\n" + rad, "bad.csv"))
    unused = read_measurement(write(tmp_path, GOOD, "r.csv"), white_reflectance=0.98)
    np.testing.assert_array_equal(unused.R, read_measurement(write(tmp_path, GOOD)).R)
    assert any("the white standard's reflectance is not used" in n for n in unused.notes)


@pytest.mark.parametrize("order", ["utf-16-le", "utf-16-be"])
def test_utf16_without_a_byte_order_mark_is_read(tmp_path, order):
    """Windows' "Unicode" saved without its mark is not "a binary file (a NUL byte)":
    plainly UTF-16 text (every other byte NUL, none of the rest) is read as it; a binary
    file with NULs is still refused."""
    plain = read_measurement(write(tmp_path, GOOD, "plain.csv"))
    path = tmp_path / "u16.csv"
    path.write_bytes(GOOD.replace("\n", "\r\n").encode(order))
    m = read_measurement(path)
    np.testing.assert_array_equal(m.R, plain.R)
    assert m.name == plain.name
    (tmp_path / "bin.csv").write_bytes(b"wavelength_nm\x00\x01\x02" * 40)
    with pytest.raises(InputError, match="a binary file"):
        read_measurement(tmp_path / "bin.csv")


def test_a_header_that_says_percent_reads_percent(tmp_path):
    """`R_inf (%)` read as fractions unless the median guesses percent makes dark percent
    data come out 100× too high. A header that
    says % reads its file as percent, with a note, even where every reading is below 1."""
    plain = read_measurement(write(tmp_path, GOOD, "plain.csv"))
    head, rows = GOOD.split("R_g\n")
    scaled = "\n".join(",".join([r.split(",")[0], *(f"{float(v) * 100:g}" for v in
                                                    r.split(",")[1:])])
                       for r in rows.strip().splitlines()) + "\n"
    for header in ("wavelength_nm,R_0.05mm (%),R_0.15mm [%],R_inf %,R_g (%)",
                   "wavelength_nm,R_0.05mm (%),R_0.15mm,R_inf,R_g"):
        m = read_measurement(write(tmp_path, head.split("\n")[0] + "\n" + header + "\n" +
                                   scaled, "pc.csv"))
        np.testing.assert_allclose(m.R, plain.R, rtol=1e-12)
        np.testing.assert_allclose(m.R_g, plain.R_g, rtol=1e-12)
        assert any("%: read as percent (/ 100)" in n for n in m.notes), m.notes
    dark = read_measurement(write(tmp_path, "wavelength_nm,R_0.05mm (%),R_inf (%),R_g (%)\n"
                                  "400,0.2,0.5,0.1\n410,0.3,0.6,0.1\n", "dark.csv"))
    np.testing.assert_allclose(dark.R_inf, [0.005, 0.006], rtol=1e-12)
    # One column says %, the others do not and read either way: dividing every column
    # turns R 0.12 into 0.0012 (exit 0); dividing only the marked one reads a black card's
    # 0.6 % as a white card's 0.6. Ambiguous: refused, naming them.
    with pytest.raises(InputError, match=r"mixed.csv: column 'R_inf \(%\)' says %, columns "
                                         r"'R_0.05mm', 'R_g' do not, and their readings "
                                         r"\(median 0.085\) could be fractions or percent"):
        read_measurement(write(tmp_path, "wavelength_nm,R_0.05mm,R_inf (%),R_g\n400,0.12,35,"
                               "0.04\n410,0.13,36,0.05\n", "mixed.csv"))
    with pytest.raises(InputError, match=r"black.csv: column 'R_0.05mm \(%\)' says %, column "
                                         r"'R_g' does not, and their readings \(median 0.605\)"):
        read_measurement(write(tmp_path, "wavelength_nm,R_0.05mm (%),R_inf (%),R_g\n400,12,35,"
                               "0.6\n410,13,36,0.61\n", "black.csv"))
    # --percent says what the unmarked ones are
    marked = read_measurement(write(tmp_path, "wavelength_nm,R_0.05mm,R_inf (%),R_g\n"
                                    "400,12,35,0.6\n410,13,36,0.61\n", "mixed.csv"),
                              percent=True)
    np.testing.assert_allclose(marked.R_g, [0.006, 0.0061], rtol=1e-12)
    np.testing.assert_allclose(marked.R_inf, [0.35, 0.36], rtol=1e-12)


def test_thousands_separators_and_lone_decimal_commas(tmp_path):
    """In a ';' file a wavelength written 1,050 must not read as 1.05: refused, naming
    both readings; a decimal comma in a '# thickness_mm:' or '# white_reflectance:' line
    (one number: nothing to confuse it with) is read as a point; a '# white_reflectance:'
    line is only checked where radiance columns use it."""
    text = ("wavelength_nm;R_0.05mm;R_inf;R_g\n1,000;0,3;0,4;0,04\n1,050;0,3;0,4;0,04\n")
    with pytest.raises(InputError, match=r"t.csv:2: column 'wavelength_nm': '1,000' reads as a "
                                         r"thousands separator"):
        read_measurement(write(tmp_path, text, "t.csv"))
    micro = read_measurement(write(tmp_path, text.replace("1,000", "0,400").replace(
        "1,050", "0,410").replace("R_0.05mm", "R_0,05mm"), "um.csv"))
    np.testing.assert_allclose(micro.wavelength_nm, [400, 410])
    # three decimals: 380000 nm is no wavelength, so 380,000 is 380 nm (it was refused)
    three = read_measurement(write(tmp_path, text.replace("1,000", "380,000").replace(
        "1,050", "390,000"), "three.csv"))
    np.testing.assert_allclose(three.wavelength_nm, [380, 390])
    np.testing.assert_allclose(micro.thickness_mm, [0.05])  # a decimal comma in the header
    bare = read_measurement(write(tmp_path, "# thickness_mm: 0,05\n" + GOOD.replace(
        "R_0.05mm", "R"), "bare.csv"))
    np.testing.assert_allclose(bare.thickness_mm, [0.05, 0.15])
    # not radiance: the line is not read (a bad value there fails nothing), with a note
    m = read_measurement(write(tmp_path, "# white_reflectance: 98\n" + GOOD, "w.csv"))
    assert any("the white standard's reflectance is not used" in n for n in m.notes)
    rad = ("# white_reflectance: 0,98\nwavelength_nm,E_0.1mm,E_inf,E_g,E_white\n"
           "400,1.0,2.0,-0.002,4.0\n410,1.5,3.0,0.3,6.0\n")
    r = read_measurement(write(tmp_path, rad, "rad.csv"))
    # E_g's -0.002 (R = -0.0005: dark-corrected noise) is read as 0, as a reflectance is
    np.testing.assert_allclose(r.R_g, [0.0, 0.049], rtol=1e-12)
    np.testing.assert_allclose(r.R[0], [0.245, 0.245], rtol=1e-12)


def test_a_hole_in_the_wavelengths_is_warned_about(tmp_path, capsys):
    """A 110 nm hole across the greens (rows lost) is bridged by a straight line, and a red
    lipstick renders orange: calibrate warns, naming the hole; regular
    steps, a small hole at 1 nm steps and a hole outside 380-780 nm are not warned about."""
    from jaxskin.cli import main
    from jaxskin.formats import wavelength_gaps

    assert wavelength_gaps(np.arange(380, 781, 5)) == []
    assert wavelength_gaps(np.arange(380, 781, 20)) == []  # a coarse instrument: its step
    one = np.arange(380, 781, 1.0)
    assert wavelength_gaps(one[(one < 500) | (one > 510)]) == []  # 11 nm: under 20 nm
    far = np.r_[np.arange(380, 781, 5), 900, 1000]
    assert wavelength_gaps(far) == []  # beyond the render grid
    hole = np.r_[np.arange(380, 496, 5), np.arange(605, 781, 5)]
    lines = wavelength_gaps(hole)
    assert len(lines) == 1 and lines[0].startswith(
        "no readings between 495 and 605 nm (110 nm, where the file's step is 5 nm)"), lines
    src = data_dir() / "measurements" / "lipstick_red.csv"
    kept = [line for line in src.read_text().splitlines()
            if not (line[:3].isdigit() and 500 <= float(line.split(",")[0]) <= 600)]
    gap = write(tmp_path, "\n".join(kept) + "\n", "gap.csv")
    assert main(["calibrate", str(gap), "-o", str(tmp_path / "out"), "--no-report"]) == 0
    err = capsys.readouterr().err
    assert (f"jaxskin: warning: {gap}: no readings between 495 and 605 nm (110 nm, where the "
            "file's step is 5 nm)") in err, err


def test_a_row_repeated_exactly_is_read_once(tmp_path):
    """An export's doubled row (the same wavelength and readings) is not refused as "must
    increase": read once, with a note naming it; the same wavelength with other
    readings is still refused."""
    plain = read_measurement(write(tmp_path, GOOD, "plain.csv"))
    lines = GOOD.splitlines()
    doubled = "\n".join(lines[:3] + [lines[2]] + lines[3:]) + "\n"  # line 4 = line 3
    m = read_measurement(write(tmp_path, doubled, "doubled.csv"))
    np.testing.assert_array_equal(m.R, plain.R)
    np.testing.assert_array_equal(m.wavelength_nm, plain.wavelength_nm)
    assert f"{tmp_path / 'doubled.csv'}: line 4 (= 3) repeats the row before: read once" in \
        m.notes, m.notes
    other = lines[2].rsplit(",", 1)[0] + ",0.0499"
    with pytest.raises(InputError, match="wavelengths must increase"):
        read_measurement(write(tmp_path, "\n".join(lines[:3] + [other] + lines[3:]) + "\n",
                               "other.csv"))


def test_a_device_or_pipe_is_refused_before_it_is_opened(tmp_path):
    """`calibrate /dev/zero` must not grow to 24 GB and ignore Ctrl-C, and a FIFO must not
    block the command forever in `open`: both refused from `os.stat`, as render refuses
    them."""
    with pytest.raises(InputError, match=r"/dev/zero: not a regular file \(a character "
                                         r"device\): expected a CSV table"):
        read_measurement("/dev/zero")
    os.mkfifo(tmp_path / "m.csv")
    with pytest.raises(InputError, match=r"m.csv: not a regular file \(a FIFO\)"):
        read_measurement(tmp_path / "m.csv")


def test_ignoring_the_wavelength_column_by_name_is_refused(tmp_path):
    """`calibrate --ignore wavelength_nm` is refused, not run as if the option were not
    given; a pattern that happens to match it (`w*`) still passes it by."""
    path = write(tmp_path, GOOD)
    with pytest.raises(InputError, match=r"m.csv:2: column 'wavelength_nm': --ignore names the "
                                         r"first column, the wavelengths, which cannot be "
                                         r"ignored"):
        read_measurement(path, ignore=["wavelength_nm"])
    assert read_measurement(path, ignore=["w*"]).wavelength_nm.size > 0
