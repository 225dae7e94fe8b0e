"""Write the bundled texture images: scenes/images/uvgrid.bmp and scenes/images/bricks.png.

uvgrid: red grows with u, green with v, and an 8 x 4 grid of dark lines — it shows how each shape maps
(u, v).  bricks: a running-bond brick wall.  Run from the repository root.
"""
import numpy as np
from PIL import Image


def uv_grid(width=256, height=128) -> np.ndarray:
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    image = np.zeros((height, width, 3))
    image[..., 0] = 0.2 + 0.8 * u[None, :]
    image[..., 1] = 0.2 + 0.8 * v[::-1, None]  # row 0 is the top: v = 1
    image[..., 2] = 0.35
    lines = (np.mod(u * 8, 1)[None, :] < 0.06) | (np.mod(v[::-1] * 4, 1)[:, None] < 0.06)
    image[lines] = 0.05
    return image


def bricks(width=128, height=128) -> np.ndarray:
    y, x = np.mgrid[0:height, 0:width]
    row = y // 16
    shifted = (x + (row % 2) * 16) % 32
    mortar = (y % 16 < 2) | (shifted < 2)
    image = np.empty((height, width, 3))
    image[:] = (0.62, 0.22, 0.15)
    image[mortar] = (0.8, 0.78, 0.72)
    return image


def save(image, path):
    Image.fromarray(np.round(image * 255).astype(np.uint8)).save(path)


if __name__ == "__main__":
    save(uv_grid(), "scenes/images/uvgrid.bmp")
    save(bricks(), "scenes/images/bricks.png")
