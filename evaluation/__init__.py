"""hyperstate.evaluation: train and deploy grids of agents × tasks × seeds; report online return.

Entry point: `python evaluation/run.py --help`.
"""
