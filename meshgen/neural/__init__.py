"""The neural method (3DMeshNet, design notes §6): a tanh MLP trained on the Winslow equations.

Modules, each usable alone:

- ``model``: the network, the exact-boundary wrapper, ``mesh_from_checkpoint`` (inference from plain data)
- ``network_map``: one network's map on a tensor grid (NumPy forward via ``mlp_numpy``; torch via
  ``gpu_forward`` on a GPU); ``inference``: the one inference path of a model, a set of networks
  (0.2's one network a set of one), and the conforming correction of a block set
- ``winslow``: the scale-free Winslow residual from first and second derivatives
- ``derivatives``: finite differences on shifted structured grids; autograd; per-point stencils
- ``losses``: point sampling, PDE loss, boundary loss with surface-point weights
- ``reweighting``: uncertainty weights a1, a2
- ``pcgrad``: gradient projection between the PDE and boundary gradients
- ``config``: the training configuration, presets, overrides
- ``checkpoint``: saving and loading plain-data checkpoints
- ``problem``: what one block's network is trained on: its map, residual, losses and point draws
  (all of a one-block geometry's terms); ``interfaces``: the terms across a block set's interfaces
  (glued stencils, interface agreement, flat patches, junctions, the pull towards the TFI)
- ``steps``: one step of each stage (the Adam step, eager or as a CUDA graph via ``cudagraph``; L-BFGS)
- ``history``: the run's state, ``history.csv`` and the divergence guard
- ``stages``: the stage runner, one training loop for a shape and for a family
- ``train``: the one training entry (a geometry's set of networks: one block, or a block set) and
  one block's stage table; ``interface_stages``: the stage table of a set of several blocks
- ``family``: a family of shapes (``--vary``), its network and meshing a member;
  ``family_train``: its stage table, losses and summary
- ``progress``: progress bar and log lines; ``session``: what ``meshgen train`` checks and runs

Nothing here is imported by ``meshgen --help``; torch is imported by the modules that need it.
"""

__all__: list[str] = []  # a namespace package: import the submodules
