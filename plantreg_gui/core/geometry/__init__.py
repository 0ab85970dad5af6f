"""Geometry on top of the cameras: depth maps to metres and points, the ToF depth clean-up, the
object and uncertainty meshes, ray casting (Open3D) and the region of interest.
"""
