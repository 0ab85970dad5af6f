"""Pure computation: camera model, rig, recordings, mesh, ray casting, registration, calibration,
export. Never imports Qt or any GUI toolkit (enforced by tests/test_architecture.py)."""
