"""Physics as small functions returning NGSolve coefficient expressions.

Nothing here knows about meshes, time steps or files: a material maps a strain
to a stress, a contact law maps boundary displacements to tractions, the bonding
law maps the state to a debonding rate. Scenes compose them; schemes step them.
"""
