"""Qt front end. Everything here only drives and shows :mod:`plantreg_gui.core`."""
