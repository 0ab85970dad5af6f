"""Entry script of the bundle's ``plantreg-gui`` (the gui script ``plantreg_gui.gui.app:main``)."""
import sys

if __name__ == "__main__":
    from plantreg_gui.gui.app import main  # calls multiprocessing.freeze_support() itself

    sys.exit(main())
