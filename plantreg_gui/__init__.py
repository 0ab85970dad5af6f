"""plantreg: multimodal 3D image registration for plant phenotyping rigs."""

__version__ = "0.1.0"
