"""The planner side's decoders under fuzzing: the search configuration and the hints file."""

from __future__ import annotations

from offboard.planning.priors import HintsFile
from offboard.search.loop import SearchConfig
from shared import toml_writer
from shared.config import ConfigError, load_config
from shared.fuzz_targets import shared_targets, toml_target
from shared.fuzzing import FuzzTarget
from shared.strict import to_plain

# A valid hints file (two tables of the paper lab and a shelf), the start of the hints cases.
HINTS = """
[[hint]]
name = "table-1"
min = [1.0, 4.3, 0.75]
max = [2.4, 5.0, 1.0]
weight = 0.5

[[hint]]
min = [6.0, 0.0, 1.5]
max = [7.5, 0.4, 1.8]
weight = 0.3
"""


def offboard_targets() -> list[FuzzTarget]:
    search = toml_writer.dumps(to_plain(SearchConfig()))
    return [
        toml_target("search config toml", lambda p: load_config(SearchConfig, p), ConfigError, [search],
                    SearchConfig),
        toml_target("hints toml", lambda p: load_config(HintsFile, p), ConfigError, [HINTS], HintsFile),
    ]


def in_process_targets() -> list[FuzzTarget]:
    """Every target this process may run: shared's and the planner side's."""
    return [*shared_targets(), *offboard_targets()]
