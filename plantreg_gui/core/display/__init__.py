"""How values become pictures: colour maps, contrast limits, PCA false colour of cubes, mosaics.
"""
