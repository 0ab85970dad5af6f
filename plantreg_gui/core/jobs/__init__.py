"""Core work in a child process (cancellable, with progress), so that GIL-holding steps do not
freeze a GUI thread: :mod:`.process_job`. How child processes meet signals: :mod:`..signals`.
"""
