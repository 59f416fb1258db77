"""thirdbody: a deformable third-body particle between two rigid plates, by FFT-accelerated BEM."""

__version__ = "0.1.0"
