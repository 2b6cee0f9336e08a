"""``meshgen compare``: arrives in a later release."""

import click


@click.command("compare", context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
def compare():
    """Not available in this version yet (see the CHANGELOG)."""
    raise click.ClickException("'meshgen compare' is not available in this version yet")
