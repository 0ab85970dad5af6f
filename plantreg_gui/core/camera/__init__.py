"""What a rig is: cameras (intrinsics, distortion, pose ``R_cam_rig``/``t_cam_rig``, the one
projection function :meth:`.camera.Camera.project`), the rig file, and the registry of imaging modalities.
"""
