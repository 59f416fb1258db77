"""Surface displacements summed cell by cell, independent of the package's FFT operators: scipy's
convolution of the cell coefficients (Love's K_zz, Cerruti's K_tt, the coupling K_zx, K_zy with
K_xz = -K_zx), for checking solutions against their equations on the whole window."""

import numpy as np
from scipy.signal import fftconvolve

from thirdbody.bem import influence


def summed(grid, mat, pressure, traction, coupled: bool = True):
    """(u_z, (u_x, u_y)) in m of a pressure (Pa) and a shear (2, ny, nx) (Pa) on the window;
    ``coupled=False``: Goodman's approximation (no K_zx terms)."""
    ny, nx = grid.shape
    dx, dy = grid.spacing
    X = np.arange(-(nx - 1), nx)[None, :] * dx
    Y = np.arange(-(ny - 1), ny)[:, None] * dy
    kzz = influence.normal(X, Y, dx / 2, dy / 2, mat.E_star)
    kxx, kxy, kyy = influence.tangential(X, Y, dx / 2, dy / 2, mat.G, mat.nu)

    def conv(field, kernel):
        return fftconvolve(field, kernel, mode="full")[ny - 1:2 * ny - 1, nx - 1:2 * nx - 1]

    tx, ty = traction
    u_z = conv(pressure, kzz)
    u_t = np.stack([conv(tx, kxx) + conv(ty, kxy), conv(tx, kxy) + conv(ty, kyy)])
    if coupled:
        kzx = influence.coupling(X, Y, dx / 2, dy / 2, mat.G, mat.nu)
        kzy = influence.coupling(Y, X, dy / 2, dx / 2, mat.G, mat.nu)
        u_z = u_z + conv(tx, kzx) + conv(ty, kzy)
        u_t = u_t - np.stack([conv(pressure, kzx), conv(pressure, kzy)])
    return u_z, u_t
