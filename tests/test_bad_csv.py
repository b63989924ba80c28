"""Bad CSV inputs, through the command line: each one exits 2 with exactly one line
`jaxskin: error: FILE[:LINE]: ...` on stderr, no traceback, nothing written under -o, and the
input file left as it was."""

import numpy as np
import pytest

from jaxskin.cli import main

HEADER = "wavelength_nm,R_0.05mm,R_0.15mm,R_inf,R_g\n"
ROWS = [(400, 0.30, 0.40, 0.45, 0.04), (410, 0.31, 0.41, 0.46, 0.04),
        (420, 0.32, 0.42, 0.47, 0.04)]


def rows(rows=ROWS, sep=","):
    return "".join(sep.join(f"{v:g}" for v in r) + "\n" for r in rows)


GOOD = "# name: good\n" + HEADER + rows()
RADIANCE = "wavelength_nm,E_0.1mm,E_inf,E_g,E_white\n400,1,2,0.2,4\n410,1.5,3,0.3,6\n"
BRDF = "theta_in_deg,phi_in_deg,theta_out_deg,phi_out_deg,R,G,B\n"
BRDF_ROW = "30,0,40,180,0.2,0.1,0.1\n"

# (id, file contents (str or bytes), line named or None, column named or None, words)
CASES = [
    ("empty file", "", None, None, "no header row"),
    # what calibrate writes, given back to it (was: 'line 4 begins with "wavelength_nm": [')
    ("a material JSON", '{\n  "name": "x",\n  "wavelength_nm": [400, 410],\n  "S_per_mm": '
     '[1, 2]\n}\n', None, None, "a JSON file, not a measurement CSV"),
    ("a material JSON in UTF-16, blank lines first", '\n\n  {"name": "x", "wavelength_nm": '
     '[400, 410]}\n'.encode("utf-16"), None, None, "a JSON file, not a measurement CSV"),
    ("blank lines only", "\n\n  \n", None, None, "no header row"),
    ("header only", HEADER, 1, None, "needs at least 2 data rows"),
    ("one data row", HEADER + rows(ROWS[:1]), 1, None, "needs at least 2 data rows"),
    ("binary garbage", bytes(np.random.default_rng(0).integers(0, 256, 4096, np.uint8)), 2,
     None, "binary"),
    ("neither UTF-8 nor Windows-1252", GOOD.encode().replace(b"# name: good",
                                                               b"# unit: \x81\x8dm"), 1, None,
     "not UTF-8 nor cp1252"),
    ("UTF-16's byte-order mark, then an odd byte", b"\xff\xfe" + "wl".encode("utf-16-le") + b"\x00",
     None, None, "not UTF-16 text"),
    ("a PNG given for the CSV", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR" + bytes(64), None, None,
     "a PNG image, not text: expected a CSV table (export it as CSV)"),
    ("an Excel workbook", b"PK\x03\x04\x14\0\x06\0" + bytes(64), None, None,
     "a ZIP archive (an Excel .xlsx workbook?), not text"),
    ("UTF-16 with a NUL character", GOOD.replace("# name: good", "# name: good\0").encode("utf-16"),
     1, None, "a binary file (a NUL character)"),
    ("mixed delimiters", GOOD.replace("0.31,0.41,0.46,0.04", "0.31;0.41;0.46;0.04"), 4, None,
     "semicolons"),
    ("ragged row, short", GOOD.replace("0.41,0.46", "0.41"), 4, None, "4 cells where"),
    ("empty last cell", GOOD.replace("0.46,0.04", "0.46,"), 4, "R_g", "empty cell"),
    ("ragged row, long", GOOD.replace("0.41,0.46", "0.41,0.46,0.5"), 4, None, "6 cells where"),
    ("NaN cell", GOOD.replace("0.41", "NaN"), 4, "R_0.15mm", "finite"),
    ("inf cell", GOOD.replace("0.46", "-inf"), 4, "R_inf", "finite"),
    ("1e308 reflectance", GOOD.replace("0.46", "1e308"), 4, "R_inf", "[0, 1]"),
    ("1e308 wavelength", GOOD.replace("420,", "1e308,"), 5, "wavelength_nm", "outside"),
    ("overflowing exponent", GOOD.replace("0.41", "1e999"), 4, "R_0.15mm", "finite"),
    ("text cell", GOOD.replace("0.41", "n/a"), 4, "R_0.15mm", "expected a number"),
    # (with ';' or tabs between columns decimal commas are read: test_measurements)
    ("decimal comma in a comma-separated file", GOOD.replace("0.41", '"0,41"'), 4,
     "R_0.15mm", "a decimal comma cannot be told from a column break"),
    ("negative reflectance", GOOD.replace("0.04\n410", "-0.01\n410"), 3, "R_g", "[0, 1]"),
    ("reflectance over 100 %", HEADER + "400,30,40,145,4\n410,31,41,46,4\n", 2, "R_inf",
     "in percent must be in [0, 100], got 145"),
    ("reflectance just over 1", GOOD.replace("0.46", "1.2"), 4, "R_inf", "--percent"),
    ("decreasing wavelengths", GOOD.replace("420,", "405,"), 5, "wavelength_nm", "increase"),
    ("duplicate wavelength", GOOD.replace("420,", "410,"), 5, "wavelength_nm", "increase"),
    ("µm and nm mixed", GOOD.replace("400,", "0.4,").replace("410,", "0.41,"), 3,
     "wavelength_nm", "nm and µm mixed"),
    ("header says µm, values nm", GOOD.replace("wavelength_nm", "wavelength_um"), 3,
     "wavelength_um", "outside"),
    ("zero wavelength", GOOD.replace("400,", "0,"), 3, "wavelength_nm", "outside"),
    ("missing R_inf", HEADER.replace(",R_inf", "") + "400,0.3,0.4,0.04\n410,0.3,0.4,0.04\n",
     1, None, "missing column R_inf"),
    ("missing R_g", HEADER.replace(",R_g", "") + "400,0.3,0.4,0.45\n410,0.3,0.4,0.45\n", 1,
     None, "missing column R_g"),
    ("thickness 0", GOOD.replace("R_0.05mm", "R_0mm"), 2, "R_0mm", "positive"),
    ("thickness negative", GOOD.replace("R_0.05mm", "R_-0.05mm"), 2, "R_-0.05mm", "positive"),
    ("thickness huge", GOOD.replace("R_0.05mm", "R_1e9mm"), 2, "R_1e9mm", "at most 100"),
    ("thickness comment not a number", "# thickness_mm: thin\n" + GOOD, 1, "key 'thickness_mm'",
     "positive"),
    ("E columns without E_white", RADIANCE.replace(",E_white", "").replace(",4\n", "\n")
     .replace(",6\n", "\n"), 1, "E_0.1mm", "E_white"),
    ("E_white zero", RADIANCE.replace(",4\n", ",0\n"), 2, "E_white", "> 0"),
    # an E column relabelled R_inf: its radiance would fit as a reflectance, "perfectly"
    ("R among E columns", RADIANCE.replace("E_inf", "R_inf"), 1, "R_inf",
     "a reflectance among radiance columns"),
    ("radiance 1e308", RADIANCE.replace("1.5,", "1e308,"), 3, "E_0.1mm", "radiance"),
    ("preamble without a header", "Spectrometer: ASD FieldSpec\nIntegration,100\nSome text\n",
     None, None, "no header row"),
    ("a 10 MB line", GOOD + "1," * 5_000_000 + "\n", 6, None, "cells where the header"),
    ("duplicate column", GOOD.replace("R_0.15mm", "R_0.05mm"), 2, "R_0.05mm", "twice"),
    ("unknown column", GOOD.replace("R_g", "R_ground"), 2, "R_ground", "unknown column"),
    ("empty header cell", GOOD.replace(",R_inf,", ",,"), 2, None, "header cell 4 is empty"),
    ("R_g equals R_inf", GOOD.replace("0.45,0.04", "0.45,0.45").replace("0.46,0.04", "0.46,0.46")
     .replace("0.47,0.04", "0.47,0.47"), 2, "R_g", "R_g equals R_inf"),
    ("a name that is a path", GOOD.replace("# name: good", "# name: ../escape"), 1, None,
     "names files"),
]

CARD = "wavelength_nm,R_over_black,R_over_white,R_g_black,R_g_white\n"
CARD_ROWS = "400,0.30,0.50,0.03,0.85\n410,0.31,0.51,0.03,0.86\n420,0.32,0.52,0.03,0.86\n"
# contrast cards (drawdowns): a column without its partner, a white part darker than the
# black, a film brighter over black everywhere, two layouts in one file
CARD_CASES = [
    ("card: a film over black without over white",
     "wavelength_nm,R_over_black,R_g_black,R_g_white\n400,0.3,0.03,0.85\n410,0.31,0.03,0.86\n",
     1, "R_over_black", "without its partner: no R_over_white"),
    ("card: the 0.05 mm film over white only",
     "wavelength_nm,R_over_black_0.02mm,R_over_white_0.02mm,R_over_white_0.05mm,R_g_black,"
     "R_g_white\n400,0.3,0.5,0.55,0.03,0.85\n410,0.31,0.51,0.55,0.03,0.86\n", 1,
     "R_over_white_0.05mm", "no R_over_black column (the 0.05 mm film)"),
    ("card: the black part without the white",
     "wavelength_nm,R_over_black,R_over_white,R_g_black\n400,0.3,0.5,0.03\n410,0.31,0.51,0.03\n",
     1, "R_g_black", "needs both R_g_black and R_g_white"),
    ("card: films without the card alone",
     "wavelength_nm,R_over_black,R_over_white\n400,0.3,0.5\n410,0.31,0.51\n", 1, None,
     "missing columns R_g_black and R_g_white"),
    ("card: the white part darker than the black",
     CARD + CARD_ROWS.replace("0.03,0.86\n420", "0.90,0.86\n420"), 3, "R_g_white",
     "not brighter than its black part"),
    ("card: the film brighter over black everywhere",
     "wavelength_nm,R_over_black,R_over_white,R_g_black,R_g_white\n400,0.5,0.3,0.03,0.85\n"
     "410,0.51,0.31,0.03,0.86\n", 1, "R_over_black", "brighter over the card's black part"),
    ("card: beside the one-background layout",
     "wavelength_nm,R_over_black,R_over_white,R_g_black,R_g_white,R_g\n"
     "400,0.3,0.5,0.03,0.85,0.03\n410,0.31,0.51,0.03,0.86,0.03\n", 1, "R_g", "one layout"),
    ("card: two films, one of unknown thickness",
     "wavelength_nm,R_over_black,R_over_white,R_over_black_0.1mm,R_over_white_0.1mm,"
     "R_g_black,R_g_white\n400,0.3,0.5,0.4,0.45,0.03,0.85\n410,0.31,0.51,0.4,0.45,0.03,0.86\n",
     1, "R_over_black", "unknown thickness beside films of known thickness"),
]

BRDF_CASES = [
    ("BRDF 1e308", BRDF + BRDF_ROW * 12 + "30,0,40,180,1e308,0.1,0.1\n", 14, "R", "[0, 1e+06]"),
    ("BRDF all zero", BRDF + "30,0,40,180,0,0,0\n" * 12, 1, "R", "every value is 0"),
    ("BRDF NaN", BRDF + BRDF_ROW * 12 + "30,0,40,180,nan,0.1,0.1\n", 14, "R", "finite"),
    ("BRDF no header", BRDF_ROW * 12, None, None, "no header row"),
]


def _run(tmp_path, capsys, contents, command):
    path = tmp_path / "in.csv"
    if isinstance(contents, str):
        contents = contents.encode("utf-8")
    path.write_bytes(contents)
    out = tmp_path / "out"
    target = [str(out)] if command == "calibrate" else [str(out / "fit.json")]
    rc = main([command, str(path), "-o", *target])
    err = capsys.readouterr().err
    assert path.read_bytes() == contents, "the input was changed"
    assert not out.exists(), "something was written"
    return path, rc, err


def test_a_windows_1252_export_reads(tmp_path):
    """Instrument software on Windows writes cp1252 (µ, curly quotes): read, not refused,
    and the numbers are the file's."""
    from jaxskin.fitting.measurements import read_measurement

    path = tmp_path / "win.csv"
    text = GOOD.replace("# name: good", "# \u201cwin\u201d blush, unit \xb5m\n# name: win")
    path.write_bytes(text.encode("cp1252"))
    m = read_measurement(path)
    assert m.name == "win"
    np.testing.assert_array_equal(m.wavelength_nm, [400, 410, 420])


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be", "utf-8-sig"])
def test_a_unicode_export_with_a_byte_order_mark_reads(tmp_path, encoding):
    """Windows instrument software saves "Unicode" text: UTF-16 with a byte-order mark, not
    a binary file. Read by the mark, as UTF-8 with one is."""
    from jaxskin.fitting.measurements import read_measurement

    path = tmp_path / "u.csv"
    text = GOOD.replace("# name: good", "# name: good\n# unit: \xb5m, \u201cblush\u201d")
    bom = {"utf-16-le": "\ufeff", "utf-16-be": "\ufeff"}.get(encoding, "")
    path.write_bytes((bom + text).encode(encoding))
    m = read_measurement(path)
    plain = tmp_path / "plain.csv"
    plain.write_text(GOOD)
    expected = read_measurement(plain)
    assert m.name == "good"
    for a in ("wavelength_nm", "R", "R_inf", "R_g", "thickness_mm"):
        np.testing.assert_array_equal(getattr(m, a), getattr(expected, a))


@pytest.mark.parametrize("contents, line, column, words",
                         [c[1:] for c in CASES + CARD_CASES + BRDF_CASES],
                         ids=[c[0] for c in CASES + CARD_CASES + BRDF_CASES])
def test_bad_csv_is_one_line_exit_2_nothing_written(tmp_path, capsys, contents, line, column,
                                                     words):
    command = "fit-brdf" if isinstance(contents, str) and contents.count("phi_") else "calibrate"
    path, rc, err = _run(tmp_path, capsys, contents, command)
    assert rc == 2, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    where = f"jaxskin: error: {path}:{line}: " if line else f"jaxskin: error: {path}: "
    assert lines[0].startswith(where), lines[0]
    if column is not None:
        named = column if column.startswith("key ") else f"column '{column}'"
        assert named in lines[0], lines[0]
    assert words in lines[0], lines[0]
    assert len(lines[0]) < 400  # one readable line, even for a 10 MB input line


def test_table_has_at_least_25_cases():
    assert len(CASES) + len(BRDF_CASES) >= 25


@pytest.mark.parametrize("option, words", [
    (["--saunderson", "0.04"], "expected K1,K2"),
    (["--saunderson", "0.04,1.5"], "expected K1,K2"),
    (["--saunderson", "0.05,0.6"], "below --saunderson K1 = 0.05"),  # the black part's 0.03
])
def test_bad_saunderson_is_one_line_exit_2_nothing_written(tmp_path, capsys, option, words):
    path = tmp_path / "card.csv"
    path.write_text(CARD + CARD_ROWS)
    out = tmp_path / "out"
    try:
        rc = main(["calibrate", str(path), "-o", str(out), *option])
    except SystemExit as e:  # argparse's own refusal of an option's value
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2 and len(err.splitlines()) == 1 and words in err, err
    assert not out.exists()


def test_brdf_samples_given_to_calibrate_point_to_fit_brdf(tmp_path, capsys):
    """fit-brdf pointed a measurement CSV to calibrate; calibrate now returns the favour."""
    path, rc, err = _run(tmp_path, capsys, BRDF + BRDF_ROW * 3, "calibrate")
    assert rc == 2 and err == (f"jaxskin: error: {path}:1: BRDF samples (angles and R, G, B), "
                               "not a measurement of spectra: fit them with 'jaxskin "
                               "fit-brdf'\n"), err
