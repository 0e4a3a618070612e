"""Scene texts shared by tests: a 100 W, 1064 nm laser 50 m south of a 1 m Lambertian
plate (reflectance 0.5), both 1 m above the origin; observer groups are appended."""

PLATE_AT_50M = """
name = "plate50"
[laser]
wavelength_nm = 1064.0
power_w = 100.0
beam_diameter_m = 0.01
divergence_rad = 0.001
position_m = [0.0, -50.0, 1.0]
aim_m = [0.0, 0.0, 1.0]
[exposure]
duration_s = 10.0
[[targets]]
name = "plate"
shape = "plate"
center_m = [0.0, 0.0, 1.0]
normal = [0.0, -1.0, 0.0]
tangent = [1.0, 0.0, 0.0]
size_m = [1.0, 1.0]
material = { model = "lambertian", reflectance = 0.5 }
"""
