"""What a recording holds on disk: the recording manifest and its images, the Plant3DImageReg data
set reader, landmark files.
"""
