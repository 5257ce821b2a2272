"""Settings with one home: the tag size lives in PlacementConfig; the discretization's is derived."""

from dataclasses import replace

from markerplace.plan.discretize.stage import DiscretizeConfig
from markerplace.plan.config import PlanConfig
from markerplace.plan.place.config import PlacementConfig


def test_discretize_tag_size_is_derived_from_placement():
    config = PlanConfig(placement=PlacementConfig(tag_size=0.3))
    assert config.discretize.tag_size == 0.3
    # whatever the discretization config says is replaced, also after dataclasses.replace
    config = replace(config, discretize=replace(DiscretizeConfig(), tag_size=9.0, grid_spacing=0.7))
    assert config.discretize.tag_size == 0.3 and config.discretize.grid_spacing == 0.7
    config = replace(config, placement=replace(config.placement, tag_size=0.2))
    assert config.discretize.tag_size == 0.2
    assert PlanConfig().discretize.tag_size == PlacementConfig().tag_size


def test_cli_sets_the_tag_size_once():
    from markerplace.cli.main import build_parser, plan_config_from_args

    args = build_parser().parse_args(["plan", "tiny", "--out", "unused", "--tag-size", "0.15"])
    config = plan_config_from_args(args)
    assert config.placement.tag_size == config.discretize.tag_size == 0.15
