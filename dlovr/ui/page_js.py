"""What the page scripts of the UI share: how a script is run as the HTML it comes with is drawn, and
how a script on the page reports to the server.

A page script (the key follower of :mod:`dlovr.ui.jog`, the timeline's hover follower of
:mod:`dlovr.ui.timeline`) reports by setting the value of a hidden text input, as an edit by hand
would: a ``GuiUpdateMessage`` for the input's widget id reaches the server's ``on_update``.
"""

from __future__ import annotations

from html import escape

POST_JS = """function post(v){window.__viserMutable&&window.__viserMutable.sendMessage(
{type:'GuiUpdateMessage',uuid:'UUID',updates:{value:v}});}"""
"""``post(v)``: set the text input ``UUID``'s value to ``v`` (nothing while the page has no connection)."""


def is_widget_id(uuid: str) -> bool:
    """Whether ``uuid`` can go into a page script as it is (letters, digits, ``-`` and ``_`` only)."""
    return bool(uuid) and all(ch.isalnum() or ch in "-_" for ch in uuid)


def with_input(script: str, uuid: str) -> str:
    """``script`` with :data:`POST_JS` put in for ``POST`` and ``uuid`` for ``UUID``, on one line.
    Raises ValueError for a ``uuid`` that is not a widget id (:func:`is_widget_id`)."""
    if not is_widget_id(uuid):
        raise ValueError(f"not a widget id: {uuid!r}")
    return script.replace("POST", POST_JS).replace("UUID", uuid).replace("\n", "")


def on_drawn(script: str) -> str:
    """An element that runs ``script`` (JavaScript) as the HTML it is put in is drawn: an image that
    fails to load runs its ``onerror`` (viser draws HTML without running its ``<script>`` elements)."""
    return f'<img alt="" src="data:," style="display:none" onerror="{escape(script, quote=True)}">'
