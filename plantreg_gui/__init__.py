"""plantreg: multimodal 3D image registration for plant phenotyping rigs."""

import os

__version__ = "0.2.0"


def prefer_one_blas_thread() -> None:
    """Let OpenBLAS use one thread unless the user set it (call before numpy is imported).

    The programs' products are small or memory-bound ((N, 3) @ (3, 3) transforms, a 204 x 204
    PCA), where OpenBLAS's thread pool only spins: measured -0.5 s of the ~3.5 s CPU of a
    paper-sized ``plantreg register``, and 6.2-6.4 -> 4.7-5.1 s CPU for a 4K registration in
    the desktop app's process (2 cores, loaded); the values are the same (each output element is computed by one thread
    either way). ``plantreg batch`` workers inherit it. Not done on import: a library user's
    process is theirs to configure.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
