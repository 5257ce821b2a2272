"""Settings with one home: the tag size lives in PlacementConfig alone; the discretization gets it
as an argument (and in its cache key), and its candidate settings are a nested CandidateConfig."""

from markerplace.plan.config import PlanConfig
from markerplace.plan.discretize.candidate_rules import CandidateConfig
from markerplace.plan.discretize.stage import DiscretizeConfig
from markerplace.plan.place.config import PlacementConfig
from markerplace.settings import walk


def test_the_tag_size_has_one_home():
    config = PlanConfig(placement=PlacementConfig(tag_size=0.3))
    assert [leaf.path for leaf in walk(config) if leaf.path.endswith("tag_size")] == ["placement.tag_size"]
    # the discretization's cache key holds the placement's tag size (a new size re-discretizes)
    assert config.discretize.cache_view(config.placement.tag_size)["tag_size"] == 0.3
    assert DiscretizeConfig().cache_view(0.2) != DiscretizeConfig().cache_view(0.3)


def test_candidate_settings_are_nested_not_copied():
    names = {leaf.path for leaf in walk(DiscretizeConfig())}
    assert "candidates.marker_spacing" in names and "marker_spacing" not in names
    assert not any(p.startswith("candidates.") and p[len("candidates."):] in ("height", "tag_size") for p in names)
    assert isinstance(DiscretizeConfig().candidates, CandidateConfig)


def test_cli_sets_the_tag_size_once():
    from markerplace.cli.main import build_parser, plan_config_from_args

    args = build_parser().parse_args(["plan", "tiny", "--out", "unused", "--tag-size", "0.15"])
    config = plan_config_from_args(args)
    assert config.placement.tag_size == 0.15
