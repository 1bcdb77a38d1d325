"""The Foxglove layout of a run, for the namespace its graph runs in.

``assets/foxglove/glocal.json`` is the layout as Foxglove exports it (``configById``, the panel
tree in ``layout``, user scripts in ``userNodes``), written for a graph in the root namespace: it
names the graph's topics by their table names (``glocal_ros.topics``), the robot model included
(a URDF layer that reads ``/robot_description``, since Foxglove's own robot_description display
listens on that one name only).

``namespaced_layout(namespace, pair_namespace)`` is that layout for a graph under ``namespace``
(``/robot1``; "" or "/" for the root), its sim/learner pair under ``pair_namespace`` relative to it
("" for a run of one pair, ``pair0`` for the first of several): every topic of the table it names,
as a topic, a message path (``/glocal/curriculum_state.total_steps``), a key of the 3D panel's
``topics`` or a quoted name in a user script's source, moves under the namespace its publisher runs
in (the curriculum's topics under the run's, the pair's under the pair's), as recorder and bridge
see them. Everything else (frames, user scripts' own output topics) stays. ``write_layout`` writes it;
a run with a Foxglove endpoint (``glocal-ros launch --foxglove``, ``ros2 launch ... foxglove:=true``)
gets it as ``RUN_DIR/foxglove-layout.json`` (``RUN_LAYOUT``), for its live graph and its bags alike.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from glocal_ros.paths import assets_dir
from glocal_ros.recording import in_namespace
from glocal_ros.topics import GRAPH_TOPICS, TopicSpec

#: The layout file of a run with a Foxglove endpoint, in its run directory.
RUN_LAYOUT = "foxglove-layout.json"
#: Quoted strings in a user script's TypeScript source: its input topics among them.
_QUOTED = re.compile(r'"([^"\\\n]*)"')


def layout_file() -> Path:
    """The shipped layout: the graph in the root namespace."""
    return assets_dir() / "foxglove" / "glocal.json"


def _table_prefix(text: str) -> TopicSpec | None:
    """The table topic ``text`` is, or whose message path it is (the longest name wins)."""
    found = None
    for spec in GRAPH_TOPICS:
        if text == spec.name or text.startswith((spec.name + ".", spec.name + "[")):
            if found is None or len(spec.name) > len(found.name):
                found = spec
    return found


def namespaced_layout(namespace: str = "", pair_namespace: str = "", layout: dict | None = None) -> dict:
    """``layout`` (default: the shipped one) with the table's topics under ``namespace`` (see the module)."""
    run = "/" + namespace.strip("/")
    pair = "/" + "/".join(part for part in (namespace.strip("/"), pair_namespace.strip("/")) if part)

    def rename(text: str) -> str:
        spec = _table_prefix(text)
        if spec is None:
            return text
        return in_namespace(pair if spec.of_pair else run, spec) + text[len(spec.name):]

    def walk(value, key: str = ""):
        if isinstance(value, dict):
            return {rename(k): walk(v, k) for k, v in value.items()}
        if isinstance(value, list):
            return [walk(item) for item in value]
        if isinstance(value, str):
            if key == "sourceCode":
                return _QUOTED.sub(lambda match: f'"{rename(match.group(1))}"', value)
            return rename(value)
        return value

    return walk(json.loads(layout_file().read_text()) if layout is None else layout)


def write_layout(path: Path, namespace: str = "", pair_namespace: str = "") -> Path:
    """``namespaced_layout`` as a layout file Foxglove imports (*Layouts* > *Import from file...*)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(namespaced_layout(namespace, pair_namespace), indent=2) + "\n")
    return path
