"""``meshgen evaluate``: arrives in a later release."""

import click


@click.command("evaluate", context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
def evaluate():
    """Not available in this version yet (see the CHANGELOG)."""
    raise click.ClickException("'meshgen evaluate' is not available in this version yet")
