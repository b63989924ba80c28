"""Independent references (issue 20, item 1): each formula against a value computed another
way than the code computes it — by hand from the paper with the published constants written
out here (never read from the library), by colour-science's own pipeline, or by a direct
numerical sum — at non-trivial points, where a wrong exponent or a dropped factor shows.

Every tolerance is about ten times the agreement measured (float64 unless said), with that
figure in a comment. benchmarks/mutation.py checks that these tests fail for a list of
one-line physics mutants."""

import math
import warnings

import colour
import jax.numpy as jnp
import numpy as np
import pytest

from jaxskin import formats, render, skin, spectral, sss, view
from jaxskin.fields import Edit, interpolate_fields
from jaxskin.mesh import Mesh
from jaxskin.shading import blinn, kelemen, lafortune


def direction(theta_deg, phi_deg):
    """The unit vector at polar angle θ from +z and azimuth φ (degrees)."""
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def rotate_z_to(n):
    """A rotation taking +z to the unit vector `n` (Rodrigues), to tilt a whole geometry."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, n)
    s, c = np.linalg.norm(axis), float(z @ n)
    if s < 1e-15:
        return np.eye(3)
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K


# ------------------------------------------------------------------ Kelemen (Huang eq. 5)

# Geometries in the normal's frame: (θ_L, φ_L, θ_V, φ_V, m). L ≠ V ≠ N everywhere, so the
# Schlick term (H·L from 0.42 to 0.91) and Beckmann's cos⁴α (cos α from 0.955 to 0.996)
# are far from 1 and a changed exponent moves the value by 10 % to 6×.
KELEMEN_CASES = [(55, 20, 35, 170, 0.3), (70, 0, 60, 180, 0.35), (40, 90, 10, 250, 0.2),
                 (80, 45, 75, 200, 0.5)]


def kelemen_by_hand(N, L, V, m, rho_s, F0=0.028):
    """Kelemen & Szirmay-Kalos 2001 as d'Eon & Luebke write it, from angles: α is the
    angle between N and the half vector, and tan²α, cos⁴α are taken of α itself."""
    H = (L + V) / np.linalg.norm(L + V)
    alpha = math.acos(float(N @ H))
    beckmann = math.exp(-math.tan(alpha) ** 2 / m ** 2) / (m ** 2 * math.cos(alpha) ** 4)
    schlick = F0 + (1 - F0) * (1 - float(H @ L)) ** 5
    return rho_s * float(N @ L) * beckmann * schlick / (2 * (1 + float(L @ V)))


@pytest.mark.parametrize("case", KELEMEN_CASES)
@pytest.mark.parametrize("tilt", [(0, 0), (25, 130)])
def test_kelemen_off_normal_by_hand(x64, case, tilt):
    t_l, p_l, t_v, p_v, m = case
    R = rotate_z_to(direction(*tilt))  # the same geometry about a tilted normal
    N, L, V = R[:, 2], R @ direction(t_l, p_l), R @ direction(t_v, p_v)
    expected = kelemen_by_hand(N, L, V, m, 0.18)
    got = float(kelemen.specular(jnp.asarray(N), jnp.asarray(L), jnp.asarray(V), m, 0.18))
    assert got == pytest.approx(expected, rel=6e-14)  # measured 5.8e-15


# ------------------------------------------------------------------ Lafortune (eq. 4.15–4.16)

# pbrt-v1's skin fit as published (constants.md), written out here.
RHO_D = [0.428425, 0.301341, 0.331054]
LOBES = [  # (Cxy, Cz, n) per lobe, RGB
    ([-1.131747, -1.016939, -0.966018], [-1.209182, -1.462488, -1.222419],
     [6.421658, 3.699932, 3.524889]),
    ([-0.546570, -0.643533, -0.638934], [0.380123, 0.410559, 0.437367],
     [3.685044, 4.266495, 4.539742]),
    ([-0.998888, -1.020153, -1.027479], [0.857998, 0.703913, 0.573625],
     [64.208486, 63.919687, 43.809866]),
]


def lafortune_by_hand(u, v):
    """ρd/π + Σ max(0, Cx ux vx + Cy uy vy + Cz uz vz)^n per channel, Cx = Cy = Cxy."""
    out = []
    for c in range(3):
        f = RHO_D[c] / math.pi
        for Cxy, Cz, n in LOBES:
            base = Cxy[c] * u[0] * v[0] + Cxy[c] * u[1] * v[1] + Cz[c] * u[2] * v[2]
            f += max(0.0, base) ** n[c]
        out.append(f)
    return np.array(out)


# Off-normal pairs, including the retro-reflection and near-mirror directions where lobes 1
# and 2 (negative Cxy: forward scattering) are large.
LAFORTUNE_CASES = [((30, 10), (40, 200)), ((60, 0), (60, 180)), ((45, 30), (20, 30)),
                   ((75, 90), (70, 270)), ((10, 0), (15, 170))]


@pytest.mark.parametrize("u, v", LAFORTUNE_CASES)
def test_lafortune_brdf_off_normal_by_hand(x64, u, v):
    u, v = direction(*u), direction(*v)
    expected = lafortune_by_hand(u, v)
    np.testing.assert_allclose(lafortune.brdf(lafortune.skin(jnp.float64), u, v), expected,
                               rtol=3e-14)  # measured 2.3e-15


def test_lafortune_shade_is_f_cos_theta_about_a_tilted_normal(x64):
    """`shade` (no ambient) is f(u, v) cos θ in the frame of a tilted normal, times one
    light scale for every direction pair and channel (the scale itself is the renderer's
    exposure, not tested here)."""
    R = rotate_z_to(direction(35, 60))
    ratios = []
    for u, v in LAFORTUNE_CASES:
        u, v = direction(*u), direction(*v)
        got = lafortune.shade(lafortune.skin(jnp.float64), R[:, 2], R @ u, R @ v, ambient=0.0,
                              light=1.0)
        ratios.append(np.asarray(got) / (lafortune_by_hand(u, v) * u[2]))
    np.testing.assert_allclose(ratios, ratios[0][0], rtol=4e-14)  # measured 3.7e-15


# ------------------------------------------------------------------ Blinn (eq. 4.12) geometry


@pytest.mark.parametrize("theta_l, phi_l, theta_v, phi_v, n", [
    (50, 0, 20, 180, 20.0), (35, 40, 25, 230, 7.0), (30, 90, 10, 270, 100.0)])
def test_blinn_geometry_by_hand(x64, theta_l, phi_l, theta_v, phi_v, n):
    """The colour mapping aside (it is being replaced): the specular term is
    I_light · r_s · cos^n γ with γ the angle between N and the half-way vector, and the
    diffuse and ambient parts are r (I_a + I_l cos θ), found here as shade's differences."""
    R = rotate_z_to(direction(20, 200))
    N, L, V = R[:, 2], R @ direction(theta_l, phi_l), R @ direction(theta_v, phi_v)
    gamma = math.acos(float(N @ (L + V)) / float(np.linalg.norm(L + V)))
    args = (jnp.asarray(N), jnp.asarray(L), jnp.asarray(V), jnp.float64(0.2), jnp.float64(0.5))
    with_spec = np.asarray(blinn.shade(*args, 0.25, n, ambient=0.3, light=0.7))
    without = np.asarray(blinn.shade(*args, 0.0, n, ambient=0.3, light=0.7))
    np.testing.assert_allclose(with_spec - without, 0.7 * 0.25 * math.cos(gamma) ** n,
                               rtol=3e-14)  # measured 2.4e-15
    dark = np.asarray(blinn.shade(*args, 0.0, n, ambient=0.0, light=0.7))
    ambient = np.asarray(blinn.shade(*args, 0.0, n, ambient=0.3, light=0.0))
    np.testing.assert_allclose(dark / ambient, 0.7 * math.cos(math.radians(theta_l)) / 0.3,
                               rtol=3e-15)  # measured 2.2e-16


# ------------------------------------------------------------------ the skin profile (SSS)

# d'Eon & Luebke 2007 (GPU Gems 3 ch. 14), written out: variances (mm²), weights R, G, B.
VARIANCES = np.array([0.0064, 0.0484, 0.187, 0.567, 1.99, 7.41])
WEIGHTS = np.array([[0.233, 0.100, 0.118, 0.113, 0.358, 0.078],
                    [0.455, 0.336, 0.198, 0.007, 0.004, 0.0],
                    [0.649, 0.344, 0.0, 0.007, 0.0, 0.0]])
TEXEL = 0.1  # mm: the narrowest Gaussian (σ = 0.08 mm) is still resolved
SIZE = 437  # pixels within 109 texels (4σ of the widest) of the centre see no border
C = SIZE // 2


def profile(r2):
    """R(r) = Σ wᵢ exp(−r²/2vᵢ)/(2πvᵢ) per mm², RGB: `(..., 3)` from r² in mm²."""
    g = np.exp(-np.asarray(r2)[..., None] / (2 * VARIANCES)) / (2 * np.pi * VARIANCES)
    return g @ WEIGHTS.T


@pytest.fixture(scope="module")
def point_and_edge():
    """The blur (FFT, float64) of a point of light and of a vertical edge, `(SIZE, SIZE, 3)`
    each; one blur call each, shared by the tests below."""
    import jax

    with jax.enable_x64(True):
        point = np.zeros((SIZE, SIZE, 3))
        point[C, C] = 1.0
        edge = np.zeros((SIZE, SIZE, 3))
        edge[:, :C] = 1.0
        return (np.asarray(sss.blur(jnp.asarray(point), TEXEL)),
                np.asarray(sss.blur(jnp.asarray(edge), TEXEL)))


def test_point_light_is_the_published_profile(point_and_edge):
    out = point_and_edge[0]
    y, x = np.mgrid[:SIZE, :SIZE] - C
    r2 = (x * x + y * y) * TEXEL ** 2
    expected = profile(r2) * TEXEL ** 2  # light per texel from a unit point
    near = r2 <= 9 * VARIANCES[-1]  # within 3σ of the widest Gaussian
    err = np.abs(out - expected)[near].max(axis=0) / expected[C, C]
    assert np.all(err < 1.2e-4), err  # measured 1.2e-5 of the peak (sampling σ = 0.8 texel)
    # Far out only the widest Gaussians remain: red at 4 mm is 53 % the 7.41 mm² one, 47 %
    # the 1.99 mm² one.
    j = int(round(4.0 / TEXEL))
    assert out[C, C + j, 0] == pytest.approx(expected[C, C + j, 0], rel=6e-4)  # meas. 6e-5


def test_point_light_total_and_radial_moments(point_and_edge):
    """∫R dA = 1 per channel; ∫r² R dA = Σ wᵢ 2vᵢ (a 2-D Gaussian's second moment)."""
    out = point_and_edge[0]
    y, x = np.mgrid[:SIZE, :SIZE] - C
    r2 = (x * x + y * y) * TEXEL ** 2
    np.testing.assert_allclose(out.sum(axis=(0, 1)), 1.0, atol=4e-13)  # measured 3.8e-14
    second = (out * r2[..., None]).sum(axis=(0, 1))
    # measured 4e-4 (red: the widest Gaussian's tails beyond the kernel's 4σ square)
    np.testing.assert_allclose(second, WEIGHTS @ (2 * VARIANCES), rtol=4e-3)
    fourth = (out * r2[..., None] ** 2).sum(axis=(0, 1))  # 2-D: ∫r⁴ G = 8v²
    np.testing.assert_allclose(fourth[1:], (WEIGHTS @ (8 * VARIANCES ** 2))[1:],
                               rtol=1e-4)  # measured 6e-6
    assert fourth[0] == pytest.approx(WEIGHTS[0] @ (8 * VARIANCES ** 2), rel=4e-2)  # 4e-3


def test_edge_is_the_direct_convolution(point_and_edge):
    """A light edge, against a direct sum over texels (not an FFT, not the library's
    kernels): each Gaussian's 1-D marginal exp(−x²/2v)/√(2πv) summed over the lit
    columns, on the row through the middle, away from the image border."""
    out = point_and_edge[1]
    cols = np.arange(109, SIZE - 109)
    lit = np.arange(C)
    x = (cols[:, None] - lit[None, :]) * TEXEL  # (cols, lit) mm
    g = np.exp(-x[..., None] ** 2 / (2 * VARIANCES)) / np.sqrt(2 * np.pi * VARIANCES)
    expected = (g.sum(axis=1) * TEXEL) @ WEIGHTS.T  # (cols, 3)
    np.testing.assert_allclose(out[C, cols], expected, atol=4e-5)  # measured 4.2e-6


# ------------------------------------------------------------------ melanin (Jacques 1998)


def test_melanin_follows_jacques_absorption_spectrum(x64):
    """skin.reflectance's optical depth is melanin × μa(λ)/μa(500 nm) with Jacques'
    μa = 6.6e11 λ^−3.33 /cm (λ in nm): at 400 nm it is 2.102×, at 700 nm 0.3261× the 500 nm
    depth (computed here from the formula, and by hand for two wavelengths)."""
    grid = spectral.Grid(step=10)
    wl = grid.wavelengths
    base = np.full(len(grid), 0.5)
    melanin = 0.8
    depth = -np.log(np.asarray(skin.reflectance(base, melanin, grid)) / base)
    mu_a = 6.6e11 * wl ** -3.33  # per cm
    np.testing.assert_allclose(depth, melanin * mu_a / (6.6e11 * 500.0 ** -3.33),
                               rtol=7e-15)  # measured 6.7e-16
    at = {int(w): d / melanin for w, d in zip(wl, depth, strict=True)}
    assert at[400] == pytest.approx(2.1023758, rel=1e-7)  # (4/5)^−3.33 = 2.10237577
    assert at[700] == pytest.approx(0.3261322, rel=1e-7)  # (7/5)^−3.33 = 0.32613217
    assert at[500] == pytest.approx(1.0, rel=1e-14)


# ------------------------------------------------------------------ eq. 3.1 (fields)


def _square_mesh():
    """Nine vertices on a flat 2 × 2 grid in z = 0 (normals +z), unit spacing."""
    v = np.array([[x, y, 0.0] for y in range(3) for x in range(3)])
    f = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 4, 7], [3, 7, 6],
                  [4, 5, 8], [4, 8, 7]])
    return Mesh("square", v, f, np.tile([0.0, 0.0, 1.0], (9, 1)), None)


def test_eq_3_1_by_hand_on_a_tiny_mesh():
    """Parallel edits of different magnitude: d(v) = Σ (λᵢ/‖p − pᵢ‖) dᵢ / Σ λᵢ/‖p − pᵢ‖
    exactly (the paper's formula). At vertex 8 = (2, 2) from edits at 0 = (0, 0), λ = 2,
    |d| = 0.5 and 2 = (2, 0), λ = 1, |d| = 1.5: w = 2/√8, 1/2."""
    mesh = _square_mesh()
    edits = [Edit(0, (0.5, 0.0, 0.0), (0.0, 0.3, 0.0), 2.0),
             Edit(2, (1.5, 0.0, 0.0), (0.0, 1.2, 0.0), 1.0)]
    d1, d2 = interpolate_fields(mesh, edits)
    w0, w2 = 2.0 / math.sqrt(8.0), 1.0 / 2.0
    np.testing.assert_allclose(d1[8], [(w0 * 0.5 + w2 * 1.5) / (w0 + w2), 0, 0], atol=1e-14)
    np.testing.assert_allclose(d2[8], [0, (w0 * 0.3 + w2 * 1.2) / (w0 + w2), 0], atol=1e-14)
    # Vertex 4 = (1, 1): both at distance √2: the mean weighted by λ alone, 2 : 1.
    np.testing.assert_allclose(d1[4], [(2 * 0.5 + 1.5) / 3, 0, 0], atol=1e-14)
    # Vertex 1 = (1, 0): distances 1 and 1.
    np.testing.assert_allclose(d2[1], [0, (2 * 0.3 + 1.2) / 3, 0], atol=1e-14)
    # The edited vertices keep their edits.
    np.testing.assert_allclose(d1[[0, 2]], [[0.5, 0, 0], [1.5, 0, 0]], atol=0)


def test_eq_3_1_direction_of_crossing_edits():
    """Edits at right angles, equal magnitude 1: the direction is eq. 3.1's weighted mean,
    (w₀, w₂)/|·| at vertex 7 = (1, 2) with w₀ = 2/√5 (from (0, 0)), w₂ = 1/√5 (from (2, 0))."""
    mesh = _square_mesh()
    edits = [Edit(0, (1.0, 0.0, 0.0), (1.0, 0.0, 0.0), 2.0),
             Edit(2, (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 1.0)]
    d1, _ = interpolate_fields(mesh, edits)
    mean = np.array([2.0, 1.0, 0.0]) / math.sqrt(5.0)
    np.testing.assert_allclose(d1[7], mean / np.linalg.norm(mean), atol=1e-14)


# ------------------------------------------------------------------ colour (colour-science)

CMFS = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
SRGB = colour.RGB_COLOURSPACES["sRGB"]


def colour_science_srgb(values, wavelengths, illuminant):
    """colour-science's own pipeline: sd_to_XYZ under the illuminant, CAT02 von Kries
    adaptation from its white to sRGB's D65, XYZ_to_RGB (linear); then each channel scaled
    so a perfect reflector is exactly white (jaxskin's documented choice, a change below
    2e-4, checked here too). **Returns:** linear sRGB `(k, 3)`."""
    I = colour.SDS_ILLUMINANTS[illuminant]

    def xyz(v):
        return colour.sd_to_XYZ(colour.SpectralDistribution(v, wavelengths), CMFS, I) / 100

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        XYZ = np.stack([xyz(v) for v in values])
        white = xyz(np.ones(len(wavelengths)))

    def to_rgb(X):
        adapted = colour.chromatic_adaptation(X, white, colour.xy_to_XYZ(SRGB.whitepoint),
                                              method="Von Kries", transform="CAT02")
        return colour.XYZ_to_RGB(adapted, "sRGB", apply_cctf_encoding=False)

    rgb_white = to_rgb(white)
    assert np.abs(rgb_white - 1).max() < 2e-4  # measured 1.6e-4 under D65, D50 and A
    return to_rgb(XYZ) / rgb_white


@pytest.mark.parametrize("illuminant", ["D65", "D50", "A"])
def test_colorchecker_through_the_renderers_encoding_matches_colour_science(x64, illuminant):
    """All 24 ColorChecker spectra colour-science ships, through `spectral.to_rgb` and the
    renderer's `encode_srgb`, against colour-science's sd_to_XYZ → chromatic_adaptation →
    XYZ_to_RGB → cctf_encoding."""
    grid = spectral.Grid(step=10, illuminant=illuminant)
    shape = colour.SpectralShape(grid.start, grid.stop, grid.step)
    checker = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    values = np.stack([sd.copy().align(shape).values for sd in checker.values()])
    linear = colour_science_srgb(values, grid.wavelengths, illuminant)
    got = np.asarray(spectral.to_rgb(jnp.asarray(values), grid))
    np.testing.assert_allclose(got, linear, atol=1.5e-14)  # measured 1.4e-15
    encoded = colour.cctf_encoding(linear, "sRGB")
    np.testing.assert_allclose(render.encode_srgb(jnp.asarray(got)), encoded,
                               atol=6e-14)  # measured 5.6e-15
    # Without white scaling, colour-science's raw pipeline: within 1.4e-4 (linear).
    assert np.abs(linear).max() > 0.5 and linear.min() < 0  # real colours, some out of gamut


# ------------------------------------------------------------------ sRGB encoding by hand


def test_srgb_encoding_by_hand(x64):
    """IEC 61966-2-1: 12.92 x below 0.0031308, 1.055 x^(1/2.4) − 0.055 above; values worked
    out by hand (0.5^(1/2.4) = 0.74915353843834, 0.18^(1/2.4) = 0.48943708957388,
    0.02^(1/2.4) = 0.19592769603435; 0.02 lies between the joint and 0.04045)."""
    x = jnp.asarray([0.0, 0.001, 0.0031308, 0.02, 0.18, 0.5, 1.0, -0.01])
    expected = [0.0, 0.01292, 0.040449936, 1.055 * 0.19592769603435 - 0.055,
                1.055 * 0.48943708957388 - 0.055, 1.055 * 0.74915353843834 - 0.055, 1.0,
                -0.1292]
    np.testing.assert_allclose(render.encode_srgb(x), expected, rtol=0,
                               atol=2e-14)  # measured 1.8e-15 (roots to 14 digits)


# ------------------------------------------------------------------ view sampling


def test_view_samples_a_checkerboard_at_texel_centres(x64):
    """Texel (i, j) has its centre at texture coordinate (j + 0.5, i + 0.5): sampled there
    the checkerboard's own value comes back; half-way between two centres, their mean;
    at a quarter, 3 : 1. Without wrap the edge clamps; with wrap it blends with the far
    column."""
    H, W = 6, 8
    board = np.indices((H, W)).sum(axis=0) % 2 * 1.0
    image = jnp.asarray(np.stack([board, 2 * board, 10 + board], -1))
    ii, jj = np.mgrid[:H, :W]
    centres = np.stack([jj + 0.5, ii + 0.5], -1)
    mask = np.ones((H, W), bool)
    np.testing.assert_allclose(view.sample(image, centres, mask, False), image, atol=0)
    between = np.stack([jj[:, :-1] + 1.0, ii[:, :-1] + 0.5], -1)  # x between columns
    np.testing.assert_allclose(view.sample(image, between, mask[:, :-1], False)[..., 0], 0.5,
                               atol=1e-15)
    quarter = np.array([[[2.25, 3.5]]])  # a quarter texel left of texel (3, 2)'s centre
    expected = 0.25 * board[3, 1] + 0.75 * board[3, 2]
    assert float(view.sample(image, quarter, [[True]], False)[0, 0, 0]) == expected
    edge = np.array([[[0.25, 0.5]]])  # left of column 0's centre
    assert float(view.sample(image, edge, [[True]], False)[0, 0, 0]) == board[0, 0]
    wrapped = 0.75 * board[0, 0] + 0.25 * board[0, W - 1]
    assert float(view.sample(image, edge, [[True]], True)[0, 0, 0]) == wrapped
    assert float(view.sample(image, edge, [[False]], True, background=7.0)[0, 0, 1]) == 7.0


def test_downsample_is_the_block_mean():
    image = np.arange(4 * 6 * 2, dtype=np.float64).reshape(4, 6, 2)
    out = np.asarray(view.downsample(jnp.asarray(image), 2))
    assert out.shape == (2, 3, 2)
    # Block (1, 2): rows 2–3, columns 4–5, channel 1: (2·6 + 4)·2 + 1 = 33, 35, 45, 47.
    assert out[1, 2, 1] == (33 + 35 + 45 + 47) / 4


# ------------------------------------------------------------------ furrows (§5.2) and fields


@pytest.mark.parametrize("x, k_scale", [(0.5, 1.3), (1.5, 0.7), (2.0, 2.0)])
def test_furrow_functions_by_hand(x, k_scale):
    """Bando 2001 §5.2 at |d| = x, written out: f_angle = 1 − 0.4x, f_length = k(4 + x),
    f_density = k(1 + 6x), f_width = kx, f_depth = 0.25x², f_limit = ⌊30 − 10x⌋."""
    from jaxskin import wrinkles

    got = [float(v) for v in wrinkles.furrow(jnp.float32(x), k_scale)]
    expected = [1 - 0.4 * x, k_scale * (4 + x), k_scale * (1 + 6 * x), k_scale * x,
                0.25 * x * x, math.floor(30 - 10 * x)]
    np.testing.assert_allclose(got, expected, rtol=1e-6)  # float32: measured 1e-7


def test_initial_fields_by_hand():
    """§3.1: d1 = (0, 1, 0) made tangent, d2 = d1 × n. On the flat mesh (n = +z):
    d1 = (0, 1, 0), d2 = (1, 0, 0); on a plane tilted about x by 30°, d1 = (0, cos², −cos·sin)
    scaled: the projection of (0, 1, 0) onto the plane."""
    from jaxskin.fields import initial_fields

    mesh = _square_mesh()
    d1, d2 = initial_fields(mesh)
    np.testing.assert_allclose(d1, np.tile([0.0, 1.0, 0.0], (9, 1)), atol=0)
    np.testing.assert_allclose(d2, np.tile([1.0, 0.0, 0.0], (9, 1)), atol=0)
    t = math.radians(30)
    n = np.array([0.0, math.sin(t), math.cos(t)])
    tilted = Mesh("tilted", mesh.vertices, mesh.faces, np.tile(n, (9, 1)), None)
    d1, _ = initial_fields(tilted)
    np.testing.assert_allclose(d1[0], [0.0, math.cos(t) ** 2, -math.cos(t) * math.sin(t)],
                               atol=1e-15)


# ------------------------------------------------------------------ a layer's highlight


def test_layer_highlight_coverage_by_hand(x64):
    """Huang et al. §3.3 with our coverage weight 1 − exp(−X / 1 µm): a layer 1.5 µm thick
    adds 1 − e^−1.5 = 0.77687 of its own Kelemen highlight (white), found as the change
    when the layer's ρ_s goes from 0 to 0.3."""
    from jaxskin.shading import layered

    grid = spectral.Grid(step=20)
    n = len(grid)
    N = jnp.asarray([[0.0, 0.0, 1.0]])
    L, V = direction(20, 0), direction(25, 180)
    args = (grid, N, L, V, 0.3, 0.9, np.full(n, 0.4), 0.3, 0.18, np.full((1, n), 30.0),
            np.full((1, n), 2.0), jnp.asarray([[0.0015]]), np.array([0.25]))
    with_h = np.asarray(layered.radiance(*args, np.array([0.3])))
    without = np.asarray(layered.radiance(*args, np.array([0.0])))
    h = 0.9 * kelemen_by_hand(np.array([0.0, 0.0, 1.0]), L, V, 0.25, 0.3)
    np.testing.assert_allclose(with_h - without, (1 - math.exp(-1.5)) * h,
                               rtol=3e-14)  # measured 3.1e-15


# ------------------------------------------------------------------ a whole render, analytic


def test_flat_skin_plane_render_by_hand(tmp_path):
    """The cosmetics model end to end on a flat square facing the camera (orthographic, no
    SSS, no layers): every pixel inside is encode_sRGB(E · rgb(R) + I_light · f_Kelemen)
    with E = I_ambient + I_light cos θ, R the NIST spectrum darkened by melanin (Jacques'
    slope), rgb by colour-science's pipeline, Kelemen by hand, the sRGB curve by
    colour-science."""
    obj = tmp_path / "plane.obj"
    obj.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvn 0 0 1\n"
                   "f 1//1 2//1 3//1\nf 1//1 3//1 4//1\n")
    from jaxskin.scene import load_scene

    light = direction(40, 30)
    scene = tmp_path / "plane.toml"
    scene.write_text(f"""
[mesh]
file = "{obj}"
projection = "planar"
[texture]
size = 32
[wrinkles]
enabled = false
[material]
model = "spectral"
[skin]
subject = 40
melanin = 0.6
roughness = 0.35
specular = 0.2
[spectral]
step = 10
illuminant = "D65"
[sss]
enabled = false
[light]
direction = [{light[0]}, {light[1]}, {light[2]}]
ambient = 0.2
intensity = 0.8
[camera]
projection = "orthographic"
size = 24
""")
    sc = load_scene(scene)
    image = np.asarray(render.render(sc.config, sc.params))
    grid = spectral.Grid(step=10)
    wl, R = formats.nist_spectrum(40)
    R = np.interp(grid.wavelengths, wl, R) * np.exp(-0.6 * (grid.wavelengths / 500) ** -3.33)
    rgb = colour_science_srgb(R[None], grid.wavelengths, "D65")[0]
    N = np.array([0.0, 0.0, 1.0])
    linear = (0.2 + 0.8 * light[2]) * rgb + 0.8 * kelemen_by_hand(N, light, N, 0.35, 0.2)
    expected = colour.cctf_encoding(linear, "sRGB")
    inside = image[4:-4, 4:-4].reshape(-1, 3)  # the square fills 90 % of the image
    np.testing.assert_allclose(inside, np.broadcast_to(expected, inside.shape),
                               atol=6e-7)  # float32 render: measured 6.3e-8
    assert np.all(image[0, 0] == 0)  # the margin is black


def test_perspective_view_by_ray_casting():
    """Each pixel of a perspective view of a tilted square sees the texture coordinate
    where the ray through its centre meets the square: cast here (eye + t·d, plane
    intersection, back to the square's own x, y, then the planar map's affine texture
    coordinates), against the rasterizer's perspective-correct barycentrics."""
    from jaxskin.projection import project
    from jaxskin.view import make_view, rotation

    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]])
    mesh = Mesh("square", v, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0, 0, 1.0], (4, 1)),
                None)
    tmap = project("planar", mesh, 40)
    n, fov, rotate = 48, 40.0, (50.0, 20.0, 0.0)
    vw = make_view(tmap, n, "perspective", fov=fov, rotate=rotate)
    R = rotation(rotate)
    focal = 1 / math.tan(math.radians(fov) / 2)
    ii, jj = np.nonzero(vw.mask)
    sx, sy = vw.shift  # the image plane shifted to centre the projected square
    assert abs(sx) + abs(sy) > 0.01
    d = np.stack([((jj + 0.5) / (n / 2) - 1 - sx) / focal,
                  (1 - (ii + 0.5) / (n / 2) - sy) / focal,
                  -np.ones(len(ii))], 1)  # camera looks down −z, pixels square
    normal = R @ np.array([0.0, 0.0, 1.0])  # the square's plane, through the origin
    t = -(vw.eye @ normal) / (d @ normal)
    q = (vw.eye + t[:, None] * d) @ R  # back to the square's own frame (R orthogonal)
    assert np.abs(q[:, 2]).max() < 1e-12
    A, *_ = np.linalg.lstsq(np.c_[v[:, :2], np.ones(4)], tmap.xy, rcond=None)  # affine
    expected = np.c_[q[:, :2], np.ones(len(q))] @ A
    assert len(ii) > 500
    np.testing.assert_allclose(vw.tex[ii, jj], expected, atol=2e-5)  # float32: measured 2.1e-6
