# imagecodecs imports its codec extensions (_imcd, _deflate, _png, _zstd, ...) by name on first
# use, which PyInstaller's import analysis cannot see: collect them all (tifffile reads whatever
# compression a user's TIFF has; the registered TIFFs use deflate with a floating-point predictor).
from PyInstaller.utils.hooks import collect_submodules

hiddenimports = collect_submodules("imagecodecs")
