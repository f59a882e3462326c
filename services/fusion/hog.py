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


_WEIGHTS = np.concatenate(_cell_weights(), axis=1)     # (2 cells, BLOCK)


@lru_cache(maxsize=16)
def _block_matrix(n: int) -> np.ndarray:
    """(n, 2 * blocks) float32: column 2 * i + c weighs each of `n` pixels along one axis
    for cell c of block i (zero outside the block), so that one matrix product sums every
    block's cells along that axis. Pixels past the last whole cell weigh nothing."""
    blocks = n // CELL - 1
    m = np.zeros((n, 2 * blocks), np.float32)
    for i in range(blocks):
        m[i * STRIDE:i * STRIDE + BLOCK, 2 * i:2 * i + 2] = _WEIGHTS.T
    m.setflags(write=False)
    return m


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
    # [-1, 0, 1] derivatives, reflected at the border (BORDER_REFLECT_101) as OpenCV's.
    dx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=1, borderType=cv2.BORDER_REFLECT_101)
    dy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=1, borderType=cv2.BORDER_REFLECT_101)
    mag, ang = cv2.cartToPolar(dx, dy, angleInDegrees=False)
    a = ang * np.float32(BINS / np.pi) - np.float32(0.5)
    lo = np.floor(a)
    upper = mag * (a - lo)
    lower = mag - upper
    # Angles lie in [0, 2 pi): a in [-0.5, 18), its floor -1..17, the bin that mod 9.
    b0 = lo.astype(np.intp) % BINS
    b1 = b0 + 1
    b1[b1 == BINS] = 0
    h, w = gray.shape
    base = _vote_base(h, w)
    votes = np.zeros(h * w * BINS, np.float32)
    votes[base + b0] = lower
    votes[base + b1] = upper
    return votes.reshape(w, h, BINS)


def block_grid(gray: np.ndarray) -> np.ndarray:
    """(nbx, nby, 4 * BINS): the normalised histogram of every block of the image on the
    block stride, block (i, j) at pixel (x, y) = (i, j) * STRIDE. Raises ValueError for an
    image smaller than one block or not 2-D uint8."""
    h, w = gray.shape[:2]
    if h < BLOCK or w < BLOCK:
        raise ValueError(f"HOG needs at least {BLOCK}x{BLOCK} pixels, got {w}x{h}")
    votes = orientation_votes(gray)             # (W, H, BINS)
    mx, my = _block_matrix(w), _block_matrix(h)
    nbx, nby = mx.shape[1] // 2, my.shape[1] // 2
    # Two small products (x then y), not per-cell loops: every block's four cells at once.
    across = (mx.T @ votes.reshape(w, h * BINS)).reshape(2 * nbx, h, BINS)
    both = my.T @ np.ascontiguousarray(across.transpose(1, 0, 2)).reshape(h, -1)
    hist = np.ascontiguousarray(both.reshape(nby, 2, nbx, 2, BINS).transpose(2, 0, 3, 1, 4))
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
    w = np.asarray(weights, np.float32).reshape(wx * wy, size)
    # Every block against every weight block at once, then each window sums its own.
    # einsum, not a BLAS product: BLAS threads on a loaded machine cost more than this.
    parts = np.einsum("ps,ks->pk", grid.reshape(nbx * nby, size), w).reshape(nbx, nby, wx, wy)
    px, py = nbx - wx + 1, nby - wy + 1
    scores = np.zeros((px, py), np.float32)
    for i in range(wx):
        for j in range(wy):
            scores += parts[i:i + px, j:j + py, i, j]
    return scores.T + np.float32(bias)
