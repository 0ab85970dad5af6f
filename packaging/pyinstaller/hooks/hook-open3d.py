# Open3D: its compiled core (pybind*.so, which loads libOpen3D and libtbb by rpath; found by
# PyInstaller's binary analysis) and its data (fonts, shaders and materials of its viewers).
# Not its TensorFlow / PyTorch operator libraries (plantreg uses neither; ~80 MB).
from PyInstaller.utils.hooks import collect_data_files

datas = collect_data_files("open3d", includes=["resources/**"])
# open3d/__init__.py imports open3d.visualization, whose draw_plotly imports Dash and Plotly
hiddenimports = ["open3d.visualization", "open3d.ml"]
