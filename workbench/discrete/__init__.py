"""Discretisation and solvers: a model on its mesh (spaces, constant matrices, the contact side), the linear solvers,
the condensed contact system, the explicit scheme's step limit.
"""
