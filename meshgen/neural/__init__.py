"""The neural method (3DMeshNet, design notes §6): a tanh MLP trained on the Winslow equations.

Modules, each usable alone:

- ``model``: the network, the exact-boundary wrapper, ``mesh_from_checkpoint`` (inference from plain data)
- ``winslow``: the scale-free Winslow residual from first and second derivatives
- ``derivatives``: finite differences on shifted structured grids; autograd; per-point stencils
- ``losses``: point sampling, PDE loss, boundary loss with surface-point weights
- ``reweighting``: uncertainty weights a1, a2
- ``pcgrad``: gradient projection between the PDE and boundary gradients
- ``config``: the training configuration, presets, overrides
- ``checkpoint``: saving and loading plain-data checkpoints
- ``train``: the training loop and the end-of-training summary
- ``progress``: progress bar and log lines; ``session``: what ``meshgen train`` checks and runs

Nothing here is imported by ``meshgen --help``; torch is imported by the modules that need it.
"""
