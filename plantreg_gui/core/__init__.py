"""Pure computation, in parts by concept (highest first; a part imports only the parts below it,
enforced by the import-linter contracts in ``pyproject.toml``):

* :mod:`.synthetic` -- scenes of known geometry: the demo rig, recordings and board sessions.
* :mod:`.calibration` -- board detection, intrinsic and extrinsic calibration, the error tables.
* :mod:`.pipeline` -- the one load -> register -> write pipeline, and ``plantreg batch``'s engine.
* :mod:`.rigfit` -- rigs from landmarks, refinement by registration agreement, silhouettes.
* :mod:`.export` -- the output folder (the one registry of output parts).
* :mod:`.display` -- values to pictures (colour maps, limits, PCA false colour, mosaics).
* :mod:`.registration` -- the method: case codes, the Registrar, mixed pixels, hits-only storage.
* :mod:`.data` -- recordings on disk, the Plant3DImageReg data set, landmark files.
* :mod:`.geometry` -- depth maps, ToF clean-up, meshes, ray casting, the region of interest.
* :mod:`.camera` -- cameras (the one projection), rigs, the registry of modalities.
* :mod:`.io`, :mod:`.jobs` -- reading and atomically writing files; work in child processes.
* :mod:`.progress`, :mod:`.validate`, :mod:`.signals`, :mod:`.errors` -- progress and cancellation,
  checks of untrusted numbers, terminating signals, the error types every part raises.

Never imports Qt or any GUI toolkit (enforced by tests/test_architecture.py).
"""
