"""Files: reading images (TIFF, PNG, JPEG, ENVI cubes, ...) and JSON with one-line errors, atomic writes.

The lowest part of the core after :mod:`..errors`, :mod:`..progress` and :mod:`..validate`: it knows
nothing about cameras or registration.
"""
