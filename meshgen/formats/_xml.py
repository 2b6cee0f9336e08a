"""XML attribute quoting for the VTK writers: ``xml.sax.saxutils``'s ``escape`` and ``quoteattr``,
the same strings, without importing ``xml.sax.saxutils`` (it imports ``urllib.request``, and with it
``http.client``, ``ssl`` and ``email``: about 10 ms of every command's start)."""

from __future__ import annotations

__all__ = ["escape", "quoteattr"]


def escape(data: str, entities: dict | None = None) -> str:
    """``data`` with &, > and < as entities, then each key of ``entities`` replaced by its value
    (``xml.sax.saxutils.escape``)."""
    data = data.replace("&", "&amp;").replace(">", "&gt;").replace("<", "&lt;")
    for key, value in (entities or {}).items():
        data = data.replace(key, value)
    return data


def quoteattr(data: str) -> str:
    """``data`` escaped (newlines and tabs as character references too) and quoted as an XML
    attribute value: in double quotes, or single ones when it holds a double quote and no single
    one, else double with &quot; (``xml.sax.saxutils.quoteattr``)."""
    data = escape(data, {"\n": "&#10;", "\r": "&#13;", "\t": "&#9;"})
    if '"' in data:
        if "'" in data:
            return '"{}"'.format(data.replace('"', "&quot;"))
        return f"'{data}'"
    return f'"{data}"'
