"""Fitting a rig to data other than a board session: landmark pairs, refinement by registration
agreement, silhouettes, and the landmark session the GUI's landmark page drives.
"""
