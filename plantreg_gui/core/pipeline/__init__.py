"""The one load -> register -> write pipeline (:mod:`.pipeline`) that ``plantreg register``,
``plantreg batch`` and the GUI's export call, and the batch engine on top of it.
"""
