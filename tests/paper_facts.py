"""Facts copied by hand from the paper (reference/morfic_paper.tex), shared by several tests."""

# The paper's Table "Morphology randomization parameters" (tab:morphology_support), column by column,
# in DESCRIPTOR_NAMES order: thigh, calf, hip, foot, base mass; hip/thigh/calf limit min, max.
PAPER_DESCRIPTORS = {
    "go2": [1.152, 0.154, 0.678, 0.040, 6.921, -1.047, 1.047, -1.571, 3.491, -2.723, -0.838],
    "go1": [0.899, 0.158, 0.510, 0.060, 4.800, -0.803, 0.803, -1.047, 4.189, -2.697, -0.916],
    "a1": [1.013, 0.166, 0.696, 0.060, 6.000, -0.803, 0.803, -1.047, 4.189, -2.697, -0.916],
    "mini_cheetah": [0.634, 0.064, 0.540, 0.060, 3.300, -1.600, 1.600, -2.600, 2.600, -2.600, -0.800],
    "aliengo": [0.639, 0.207, 1.000, 0.060, 11.644, -1.222, 1.222, -3.142, 3.142, -2.775, -0.646],
    "anymal_c": [0.740, 0.337, 0.740, 0.250, 18.210, -0.720, 0.720, -1.650, 4.050, -2.720, -0.780],
    "b1": [4.300, 1.050, 2.150, 0.050, 29.450, -0.750, 0.750, -1.000, 3.500, -2.600, -0.600],
}

# The same table's "Train min" / "Train max" columns.
TRAIN_MIN = [0.634, 0.064, 0.510, 0.000, 3.300, -1.100, 0.800, -1.650, 3.490, -2.720, -0.950]
TRAIN_MAX = [1.152, 0.166, 0.696, 0.060, 6.921, -0.800, 1.100, -1.050, 4.050, -2.600, -0.780]
