"""Scene input: the parameter table, scenes and scene files, bodies and meshes, the model and the numerical options
built from a scene.
"""
