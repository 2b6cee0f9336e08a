"""The neural method on the smoothed boundary layout: the configuration key and the geometry hook."""

from __future__ import annotations

import numpy as np
import pytest
from neural_helpers import tiny_config

from meshgen.geometry.layout import smoothed, trained_layout
from meshgen.methods.tfi import parametric_grid, tfi
from meshgen.neural.config import ConfigError
from meshgen.neural.model import mesh_from_checkpoint
from meshgen.neural.train import train


@pytest.mark.parametrize("layout", ["smoothed", "fixed"])
def test_an_untrained_exact_network_is_the_tfi_of_its_layout(tmp_path, semicylinder, layout):
    """N starts at zero in the exact variant: before any step the map is the TFI of the boundary it
    learns, so the mesh shows which layout training and meshing took (any dims, not the fine grid's)."""
    config = tiny_config("pretrain.steps=0", "adam.steps=0", "lbfgs.steps=0", f"boundary_layout={layout}", preset="exact")
    result = train(config, semicylinder, tmp_path, summary=False)
    assert trained_layout(result.checkpoint) == layout
    coords = parametric_grid((5, 4, 7))
    X = mesh_from_checkpoint(result.checkpoint, coords, semicylinder)
    expected = tfi(smoothed(semicylinder) if layout == "smoothed" else semicylinder, (5, 4, 7))
    np.testing.assert_allclose(X, expected, rtol=0, atol=1e-6)  # float32 network output times a bubble
    assert np.abs(tfi(smoothed(semicylinder), (5, 4, 7)) - tfi(semicylinder, (5, 4, 7))).max() > 1e-2
    # A checkpoint from before the key existed was trained on the fixed layout.
    old = {**result.checkpoint, "config": {k: v for k, v in result.checkpoint["config"].items() if k != "boundary_layout"}}
    assert trained_layout(old) == "fixed"
    np.testing.assert_allclose(mesh_from_checkpoint(old, coords, semicylinder), tfi(semicylinder, (5, 4, 7)), rtol=0, atol=1e-6)


def test_unknown_layout_in_the_configuration_is_an_error():
    with pytest.raises(ConfigError, match="boundary_layout"):
        tiny_config("boundary_layout=wavy")
