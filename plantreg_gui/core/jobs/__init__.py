"""Running core work in a child process (cancellable, with progress), so that the GIL-holding
steps of Open3D do not freeze a GUI thread.
"""
