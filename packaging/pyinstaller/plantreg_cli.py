"""Entry script of the bundle's ``plantreg`` (the console script ``plantreg_gui.cli:entry``)."""
import multiprocessing

if __name__ == "__main__":
    # a spawned worker (plantreg batch, the landmark refine) re-runs this executable: let it be one
    multiprocessing.freeze_support()
    from plantreg_gui.cli import entry

    entry()
