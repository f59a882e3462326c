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
of OpenCV's `compute` (tests/fusion/test_hog.py holds reference values from it).
"""

import cv2
import numpy as np

CELL = 8
BLOCK = 16
STRIDE = 8
BINS = 9
CLIP = 0.2                      # L2-Hys
_SIGMA = (BLOCK + BLOCK) / 8.0  # OpenCV's default winSigma
_GAMMA = np.sqrt(np.arange(256, dtype=np.float32))


def _block_weights() -> np.ndarray:
    """(2, 2, BLOCK, BLOCK): the weight of each pixel of a block in cell (cx, cy): the
    Gaussian window times the bilinear split between neighbouring cells."""
    idx = np.arange(BLOCK, dtype=np.float32)
    d = idx - BLOCK * 0.5
    gauss = np.exp(-(d[:, None] ** 2 + d[None, :] ** 2) / (2.0 * _SIGMA ** 2))
    pos = (idx + 0.5) / CELL - 0.5              # position in cell units
    lower = np.floor(pos)
    frac = pos - lower
    # Weight towards cell 0 and cell 1 along one axis (pixels in the outer half cells
    # vote only for their own cell, with the bilinear weight, as OpenCV does).
    along = np.zeros((2, BLOCK), np.float32)
    for c in (0, 1):
        along[c] = np.where(lower == c, 1.0 - frac, 0.0) + np.where(lower + 1 == c, frac, 0.0)
    # [cx, cy, row, col]
    w = along[None, :, :, None] * along[:, None, None, :] * gauss[None, None]
    return w.astype(np.float32)


_WEIGHTS = _block_weights().reshape(4, BLOCK * BLOCK)


def orientation_votes(gray: np.ndarray) -> np.ndarray:
    """(H, W, BINS) float32: each pixel's gradient magnitude split between its two
    nearest orientation bins. Raises ValueError for an image that is not 2-D uint8."""
    if gray.ndim != 2 or gray.dtype != np.uint8:
        raise ValueError(f"HOG needs a 2-D uint8 image, got {gray.dtype} {gray.shape}")
    img = _GAMMA[gray]
    pad = cv2.copyMakeBorder(img, 1, 1, 1, 1, cv2.BORDER_REFLECT_101)
    dx = pad[1:-1, 2:] - pad[1:-1, :-2]
    dy = pad[2:, 1:-1] - pad[:-2, 1:-1]
    mag, ang = cv2.cartToPolar(dx, dy, angleInDegrees=False)
    a = ang * np.float32(BINS / np.pi) - np.float32(0.5)
    lo = np.floor(a)
    frac = a - lo
    b0 = lo.astype(np.int64) % BINS
    b1 = (b0 + 1) % BINS
    h, w = gray.shape
    votes = np.zeros((h * w, BINS), np.float32)
    rows = np.arange(h * w)
    votes[rows, b0.ravel()] += (mag * (1.0 - frac)).ravel()
    votes[rows, b1.ravel()] += (mag * frac).ravel()
    return votes.reshape(h, w, BINS)


def block_grid(gray: np.ndarray) -> np.ndarray:
    """(nbx, nby, 4 * BINS): the normalised histogram of every block of the image on the
    block stride, block (i, j) at pixel (x, y) = (i, j) * STRIDE. Raises ValueError for an
    image smaller than one block or not 2-D uint8."""
    h, w = gray.shape[:2]
    if h < BLOCK or w < BLOCK:
        raise ValueError(f"HOG needs at least {BLOCK}x{BLOCK} pixels, got {w}x{h}")
    votes = orientation_votes(gray)
    win = np.lib.stride_tricks.sliding_window_view(votes, (BLOCK, BLOCK), axis=(0, 1))
    win = win[::STRIDE, ::STRIDE]                # (nby, nbx, BINS, BLOCK, BLOCK)
    nby, nbx = win.shape[:2]
    pixels = win.reshape(nby, nbx, BINS, BLOCK * BLOCK)
    hist = np.einsum("yxbp,cp->xycb", pixels, _WEIGHTS, optimize=True)
    hist = hist.reshape(nbx, nby, 4 * BINS)
    size = 4 * BINS
    scale = 1.0 / (np.sqrt(np.sum(hist * hist, axis=2, keepdims=True)) + size * 0.1)
    hist = np.minimum(hist * scale, CLIP)
    scale = 1.0 / (np.sqrt(np.sum(hist * hist, axis=2, keepdims=True)) + 1e-3)
    return (hist * scale).astype(np.float32)


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
    views = np.lib.stride_tricks.sliding_window_view(grid, (wx, wy), axis=(0, 1))
    # views: (nbx - wx + 1, nby - wy + 1, size, wx, wy)
    scores = np.einsum("xysij,ijs->yx", views, w, optimize=True)
    return scores + np.float32(bias)
