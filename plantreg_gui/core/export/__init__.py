"""Writing a registration result to an output folder (the one registry of output parts).
"""
