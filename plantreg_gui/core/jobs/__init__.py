"""Child processes and signals: core work in a child process (cancellable, with progress), so
that GIL-holding steps do not freeze a GUI thread (:mod:`.process_job`), and the one handling of
terminating signals for every thread and child process (:mod:`.signals`).
"""
