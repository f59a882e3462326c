"""Histograms of oriented gradients (Dalal and Triggs), computed as OpenCV 4's
`HOGDescriptor()` computes them, so that its pedestrian detector's coefficients apply.

OpenCV 5 no longer ships `HOGDescriptor` in its main package; this module is the one HOG
of the project (pure numpy and OpenCV core). Layout and arithmetic follow OpenCV's
default descriptor: 8x8-pixel cells, 16x16-pixel blocks on an 8-pixel stride, 9
unsigned orientation bins, square-root gamma, centred [-1, 0, 1] derivatives (reflected
at the image's border), votes split between the two nearest bins and the four nearest
cells, a Gaussian window over each block (sigma 4), L2-Hys normalisation (clipped at
0.2). A descriptor orders its blocks column by column (x outer, y inner), the cells of a
block the same way, then the bins; for a 64x128 window that is 3780 numbers, the order
of OpenCV's `compute` (tests/data/hog_reference.json holds reference values from it).

Cost: no Python loop over cells or bins. Each pixel's two votes go into one array by
index; the Gaussian and bilinear weights of every block are then two small matrix
products (along x, then y) of a (4, 8) weight matrix with the cells; a 32x64 window
costs about 80 us on one core.
"""

from functools import lru_cache

import cv2
import numpy as np

CELL = 8
BLOCK = 16
STRIDE = 8
BINS = 9
CLIP = 0.2                      # L2-Hys
_SIGMA = (BLOCK + BLOCK) / 8.0  # OpenCV's default winSigma
_GAMMA = np.sqrt(np.arange(256, dtype=np.float32))


def _cell_weights() -> tuple[np.ndarray, np.ndarray]:
    """The weight of each pixel of a block for its cells, separable as OpenCV's is (a
    Gaussian window times the bilinear split between neighbouring cells, each a product
    over the two axes): (first, second) half of the block, each (2 cells, CELL) along one
    axis. Pixels in a block's outer half cells vote only for their own cell, with the
    bilinear weight, as in OpenCV."""
    idx = np.arange(BLOCK, dtype=np.float64)
    gauss = np.exp(-((idx - BLOCK * 0.5) ** 2) / (2.0 * _SIGMA ** 2))
    pos = (idx + 0.5) / CELL - 0.5              # position in cell units
    lower = np.floor(pos)
    frac = pos - lower
    along = np.zeros((2, BLOCK))
    for c in (0, 1):
        along[c] = np.where(lower == c, 1.0 - frac, 0.0) + np.where(lower + 1 == c, frac, 0.0)
    w = (along * gauss).astype(np.float32)
    return np.ascontiguousarray(w[:, :CELL]), np.ascontiguousarray(w[:, CELL:])


# A cell's pixels weighed for each cell of the block it starts (rows 0, 1) and of the
# block it ends (rows 2, 3): (4, CELL).
_CELL_WEIGHTS = np.concatenate(_cell_weights(), axis=0)


# The two bins a pixel votes for, indexed by floor(a) + 1 for floor(a) in -1..18.
_LOWER_BIN = np.arange(-1, 19) % BINS
_UPPER_BIN = np.arange(0, 20) % BINS


@lru_cache(maxsize=16)
def _vote_base(h: int, w: int) -> np.ndarray:
    """(h, w) intp: where pixel (y, x)'s bins start in a flat (w, h, BINS) vote array."""
    base = (np.arange(w)[None, :] * h + np.arange(h)[:, None]) * BINS
    base.setflags(write=False)
    return base


def orientation_votes(gray: np.ndarray) -> np.ndarray:
    """(W, H, BINS) float32, column-major: each pixel's gradient magnitude split between
    its two nearest orientation bins. Raises ValueError for an image that is not 2-D
    uint8."""
    if gray.ndim != 2 or gray.dtype != np.uint8:
        raise ValueError(f"HOG needs a 2-D uint8 image, got {gray.dtype} {gray.shape}")
    img = cv2.LUT(gray, _GAMMA)
    # Centred [-1, 0, 1] derivatives, reflected at the border as OpenCV's.
    pad = cv2.copyMakeBorder(img, 1, 1, 1, 1, cv2.BORDER_REFLECT_101)
    dx = pad[1:-1, 2:] - pad[1:-1, :-2]
    dy = pad[2:, 1:-1] - pad[:-2, 1:-1]
    mag, ang = cv2.cartToPolar(dx, dy, angleInDegrees=False)
    a = np.multiply(ang, np.float32(BINS / np.pi), out=ang)
    a -= np.float32(0.5)
    lo = np.floor(a)
    upper = np.multiply(mag, np.subtract(a, lo, out=a), out=a)
    lower = np.subtract(mag, upper, out=mag)
    # Angles lie in [0, 2 pi): a in [-0.5, 18), its floor -1..17; the two bins, mod 9.
    step = lo.astype(np.intp)
    step += 1
    h, w = gray.shape
    base = _vote_base(h, w)
    votes = np.zeros(h * w * BINS, np.float32)
    votes[base + _LOWER_BIN[step]] = lower
    votes[base + _UPPER_BIN[step]] = upper
    return votes.reshape(w, h, BINS)


def block_grid(gray: np.ndarray) -> np.ndarray:
    """(nbx, nby, 4 * BINS): the normalised histogram of every block of the image on the
    block stride, block (i, j) at pixel (x, y) = (i, j) * STRIDE. Raises ValueError for an
    image smaller than one block or not 2-D uint8."""
    h, w = gray.shape[:2]
    if h < BLOCK or w < BLOCK:
        raise ValueError(f"HOG needs at least {BLOCK}x{BLOCK} pixels, got {w}x{h}")
    votes = orientation_votes(gray)             # (W, H, BINS)
    ncx, ncy = w // CELL, h // CELL
    nbx, nby = ncx - 1, ncy - 1
    # Each cell's weighed sums along x for the two blocks it belongs to, as one small
    # product per cell column; a block adds its first cell's and its second's.
    cells = votes.reshape(w, h * BINS)[:ncx * CELL].reshape(ncx, CELL, h * BINS)
    sums = _CELL_WEIGHTS @ cells                # (ncx, 4, H * BINS)
    across = sums[:-1, :2] + sums[1:, 2:]       # (nbx, 2 cx, H * BINS)
    # The same along y, y brought first.
    rows = across.reshape(nbx * 2, h, BINS).transpose(1, 0, 2)[:ncy * CELL]
    cells = np.ascontiguousarray(rows).reshape(ncy, CELL, nbx * 2 * BINS)
    sums = _CELL_WEIGHTS @ cells                # (ncy, 4, nbx * 2 * BINS)
    both = (sums[:-1, :2] + sums[1:, 2:]).reshape(nby, 2, nbx, 2, BINS)
    hist = np.ascontiguousarray(both.transpose(2, 0, 3, 1, 4))  # (nbx, nby, cx, cy, BINS)
    return _l2_hys(hist.reshape(nbx, nby, 4 * BINS))


def _l2_hys(hist: np.ndarray) -> np.ndarray:
    """Each block (last axis) L2-normalised, clipped at CLIP, L2-normalised again, with
    OpenCV's constants; in place, float32."""
    flat = hist.reshape(-1, hist.shape[-1])
    for eps, clip in ((np.float32(flat.shape[1] * 0.1), True), (np.float32(1e-3), False)):
        scale = np.einsum("ij,ij->i", flat, flat)
        np.sqrt(scale, out=scale)
        scale += eps
        np.reciprocal(scale, out=scale)
        flat *= scale[:, None]
        if clip:
            np.minimum(flat, np.float32(CLIP), out=flat)
    return hist


def descriptor(gray: np.ndarray) -> np.ndarray:
    """The HOG descriptor of a whole window (its size a multiple of CELL, at least one
    block), flat, in OpenCV's order. Raises ValueError (see `block_grid`)."""
    return block_grid(gray).ravel()


def window_scores(grid: np.ndarray, weights: np.ndarray, bias: float,
                  win_blocks: tuple[int, int]) -> np.ndarray:
    """A linear detector `weights . descriptor + bias` at every window position of a block
    grid: (positions_y, positions_x) scores, windows on the block stride. `win_blocks`:
    the window's blocks (across, down). Raises ValueError when the grid is smaller than a
    window or the weights do not fit it."""
    wx, wy = win_blocks
    nbx, nby, size = grid.shape
    if nbx < wx or nby < wy:
        raise ValueError(f"a {nbx}x{nby}-block grid holds no {wx}x{wy}-block window")
    w = np.asarray(weights, np.float32).reshape(wx, wy, size)
    # Each window position dotted with the weights on a view of the grid (no copies).
    # einsum, not a BLAS product: BLAS threads on a loaded machine cost more than this.
    windows = np.lib.stride_tricks.sliding_window_view(grid, (wx, wy), axis=(0, 1))
    scores = np.einsum("xysij,ijs->xy", windows, w)
    return scores.T + np.float32(bias)
