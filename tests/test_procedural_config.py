"""Parameters of the procedural dancer: styles, TOML files, --param overrides, and their validation."""

from __future__ import annotations

import pytest

from dancesynth.engines.procedural import STYLES, ProceduralConfig, load_config, make_config, parse_params
from dancesynth.errors import InputError


def test_styles_toml_and_params_apply_in_order(tmp_path):
    cfg = tmp_path / "look.toml"
    cfg.write_text('style = "calm"\nl1 = 0.3\nw1 = 2\n')
    loaded = load_config(cfg)
    assert loaded.l1 == 0.3 and loaded.w1 == 2.0 and loaded.nod == STYLES["calm"]["nod"]
    final = make_config(config_path=cfg, params=["l1=0.4", "max_segment_notes=20"], fps=60)
    assert (final.l1, final.max_segment_notes, final.fps) == (0.4, 20, 60)
    assert make_config(style="e1").l1 > make_config(style="e2").l1
    table = tmp_path / "table.toml"
    table.write_text("[procedural]\nbounce = 0.2\n")
    assert load_config(table).bounce == 0.2


@pytest.mark.parametrize("text, message", [
    ("l1 = ", "not a valid TOML"),
    ("wobble = 1", "unknown parameter 'wobble'"),
    ("l1 = 'big'", "must be a number"),
    ("bounce = 3", "bounce must be between 0 and 1"),
    ('style = "disco"', "unknown procedural style"),
    ("w1 = 0\nw2 = 0\nw3 = 0\nw4 = 0", "cannot all be 0"),
    ("reach = 1.5", "reach must be"),
])
def test_bad_config_files(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        load_config(path)


def test_bad_params():
    with pytest.raises(InputError, match="name=value"):
        parse_params(["l1"], ProceduralConfig())
    with pytest.raises(InputError, match="0 or more"):
        parse_params(["l2=-1"], ProceduralConfig())
    with pytest.raises(InputError, match="finite"):
        parse_params(["l2=nan"], ProceduralConfig())
    with pytest.raises(InputError, match="no such config file"):
        load_config("/nonexistent/look.toml")
    with pytest.raises(InputError, match="not both"):
        make_config(style="calm", config_path=__file__)
