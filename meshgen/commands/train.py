"""``meshgen train``: arrives in a later release."""

import click


@click.command("train", context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
def train():
    """Not available in this version yet (see the CHANGELOG)."""
    raise click.ClickException("'meshgen train' is not available in this version yet")
