"""The page scripts' shared way to report to the server (dlovr.ui.page_js)."""

from __future__ import annotations

import pytest

from dlovr.ui.jog import keys_js
from dlovr.ui.page_js import POST_JS, on_drawn, with_input
from dlovr.ui.timeline import _pick_handlers


def test_both_page_scripts_post_through_the_one_function_to_their_input():
    post = POST_JS.replace("UUID", "in-1").replace("\n", "")
    keys, pick = keys_js("in-1"), _pick_handlers("in-1")  # pick: in 3 handler attributes
    for script, copies in ((keys, 1), (pick, 3)):
        assert script.count(post) == copies and "sendMessage" not in script.replace(post, "")
        assert "UUID" not in script and "POST" not in script and "\n" not in script
    assert '"' not in POST_JS  # it goes into the timeline's double-quoted handler attributes


@pytest.mark.parametrize("uuid", ["", "a'b", 'a"b', "a b", "a;b"])
def test_a_widget_id_that_is_not_one_is_refused(uuid: str):
    with pytest.raises(ValueError, match="not a widget id"):
        with_input("POST", uuid)
    with pytest.raises(ValueError, match="not a widget id"):
        keys_js(uuid)
    assert _pick_handlers(uuid) == ""


def test_a_script_run_as_its_html_is_drawn_is_escaped_for_its_attribute():
    html = on_drawn("document.title=\"a<b\" && f('x')")
    assert html.startswith('<img alt="" src="data:," style="display:none" onerror="')
    assert html.count('"') == 8 and "<b" not in html.removeprefix("<img")  # nothing leaves the attribute
