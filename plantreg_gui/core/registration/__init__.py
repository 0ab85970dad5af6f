"""The registration method (Stumpe et al.): case and area codes, the Registrar (meshes, target
rays, source cameras), mixed-pixel flags, hits-only image storage, region statistics.
"""
