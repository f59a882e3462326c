"""The scenario generator: every family's grid builds valid scenarios, cases are
deterministic per seed, the seed splits are disjoint, and the nominal cases are what
they claim (a threat collides when nothing brakes, a no-threat case does not)."""

import itertools
import math
import tomllib

import msgspec
import pytest

from aeb_radar_camera.tools.messages import Lighting, ObjectKind
from aeb_radar_camera.tools.sim.families import (
    EGO_WIDTH_M,
    FAMILIES,
    SPLITS,
    Case,
    all_cases,
    case_of,
    main,
    seeds_of,
    split_of,
)
from aeb_radar_camera.tools.sim.scenario import Scenario, ScenarioKind, load_scenario, scenario_toml
from aeb_radar_camera.tools.sim.world import World

DT = 0.02
# Families whose objects never fall behind the ego (they keep ahead, or drive away).
ENDLESS = {"lead_pulling_away"}
# Families whose driver brakes to a stop before the object ([driver] brake_at_s).
DRIVER_STOPS = {"override_brake"}


def drive_unbraked(sc: Scenario) -> World:
    world = World(sc)
    while world.t_s < sc.duration_s and world.collision is None and not (
            sc.kind is ScenarioKind.NO_THREAT and world.passed_everything()):
        world.step(DT, 0.0)
    return world


def check_outcome(case: Case, sc: Scenario, world: World) -> None:
    if sc.kind is ScenarioKind.THREAT:
        assert world.collision is not None, f"{case.name}: a threat case must collide"
        assert world.collision.ego_speed_mps == pytest.approx(case.speed_kph / 3.6)
    else:
        assert world.collision is None, f"{case.name}: hit {world.collision}"
        if case.family in DRIVER_STOPS:
            assert world.ego.speed_mps == 0.0, f"{case.name}: the driver stops"
        elif case.family not in ENDLESS:
            assert world.passed_everything(), f"{case.name}: the ego passes everything"


NOMINAL = list(all_cases([0]))


def test_every_family_is_listed_with_a_grid_and_the_euro_ncap_names():
    assert {"CCRs", "CCRm", "CCRb", "CPNA-25", "CPNA-75", "CPFA-50", "CPNC-50", "CPLA-25",
            "CPLA-50", "CBNA-50", "CBLA-25", "CBLA-50"} <= set(FAMILIES)
    for fam in FAMILIES.values():
        assert fam.grid(), fam.name
        assert all(10 <= v <= 60 for v, _ in fam.grid())
    assert {v for c in NOMINAL for v in [c.speed_kph]} == {10, 20, 30, 40, 50, 60}
    ccrs = FAMILIES["CCRs"].grid()
    assert {dict(p)["offset"] for _, p in ccrs} == {-50, -25, 0, 25, 50}
    assert {tuple(sorted(dict(p).items())) for _, p in FAMILIES["CCRb"].grid()} == {
        (("decel_mps2", d), ("gap_m", g)) for d in (2.0, 6.0) for g in (12.0, 40.0)}
    # The generic obstacles cover every obstacle kind, day and dusk.
    kinds = {dict(p)["object"] for f in ("obstacle_standing", "obstacle_crossing")
             for _, p in FAMILIES[f].grid()}
    assert kinds == {k.value for k in ObjectKind if k.is_obstacle}
    sizes = [float(dict(p)["size_m"]) for _, p in FAMILIES["obstacle_standing"].grid()]
    assert min(sizes) == 0.4 and max(sizes) <= 2.0


@pytest.mark.parametrize("case", NOMINAL, ids=lambda c: c.name)
def test_nominal_cases_collide_without_braking_exactly_when_they_are_threats(case):
    sc = case.scenario()
    assert sc.name == case.name and sc.ego.speed_kph == case.speed_kph
    # A plain scenario: it goes through the TOML schema and back unchanged.
    assert msgspec.convert(tomllib.loads(scenario_toml(sc)), Scenario) == sc
    check_outcome(case, sc, drive_unbraked(sc))


VARIANTS = [Case(f.name, v, p, s) for f in FAMILIES.values()
            for (v, p) in (f.grid()[0], f.grid()[-1])
            for s in (SPLITS["train"][0], SPLITS["heldout"][0], SPLITS["heldout"][1])]


@pytest.mark.parametrize("case", VARIANTS, ids=lambda c: c.name)
def test_randomised_variants_keep_their_family_s_outcome(case):
    sc = case.scenario()
    check_outcome(case, sc, drive_unbraked(sc))


def test_cases_are_deterministic_per_seed_and_vary_between_seeds():
    case = case_of("CPNA-25", 30.0, light="day", seed=2001)
    assert case.scenario() == Case(case.family, case.speed_kph, case.params, 2001).scenario()
    nominal = case_of("CPNA-25", 30.0, light="day").scenario()
    variants = [case_of("CPNA-25", 30.0, light="day", seed=s).scenario()
                for s in SPLITS["heldout"][:8]]
    assert len({msgspec.json.encode(v) for v in variants}) == 8
    # Variants move around the nominal case: the pedestrian's start, size and pace.
    ped = [v.object[0] for v in variants]
    assert len({p.y_m for p in ped}) == 8 and len({p.size() for p in ped}) == 8
    assert all(abs(p.y_m - nominal.object[0].y_m) <= 0.5 for p in ped)
    assert {v.lighting for v in variants} <= {Lighting.DAY, Lighting.DUSK}
    assert nominal.lighting is Lighting.DAY and nominal.camera.noise == 2.0
    # The nominal case has no randomness at all.
    assert nominal.object[0].size() == (0.35, 0.55, 1.75)


def test_seed_splits_are_disjoint_and_named():
    for (a, ra), (b, rb) in itertools.combinations(SPLITS.items(), 2):
        assert not set(ra) & set(rb), (a, b)
    assert split_of(0) == "nominal" and split_of(1500) == "train" and split_of(2000) == "heldout"
    with pytest.raises(ValueError, match="no split"):
        split_of(500)
    assert seeds_of("train:3") == [1000, 1001, 1002]
    assert seeds_of("heldout:2") == [2000, 2001]
    assert seeds_of("nominal") == [0]
    assert seeds_of("2000-2002") == [2000, 2001, 2002]
    assert seeds_of("0,1005") == [0, 1005]


def test_impact_points_follow_euro_ncap():
    """Crossing targets are hit at 25 / 50 / 75 % of the ego's front from the side they
    come from; CCR targets are offset by their overlap."""
    for family, expected in (("CPNA-25", -EGO_WIDTH_M / 4), ("CPNA-75", EGO_WIDTH_M / 4),
                             ("CPFA-50", 0.0), ("CBNA-50", 0.0), ("CPNC-50", 0.0)):
        for v in (10.0, 40.0, 60.0):
            case = next(c for c in FAMILIES[family].cases() if c.speed_kph == v)
            world = drive_unbraked(case.scenario())
            assert world.collision is not None
            target = world.bodies()[world.collision.object_index]
            assert target.kind in (ObjectKind.PEDESTRIAN, ObjectKind.BICYCLE)
            assert target.y_m == pytest.approx(expected, abs=0.12), (family, v)
    sc = case_of("CCRs", 40.0, offset=-50).scenario()
    assert sc.object[0].y_m == pytest.approx(-0.9)


def test_the_cbna_cyclist_rides_its_last_17_m_at_speed_and_the_kerb_cyclist_its_last_5():
    """Euro NCAP's CBNA: at 15 km/h over the last 17 m before the impact point (its
    steady-state distance), at every ego speed and seed; `cyclist_from_kerb` sets off 5 m
    from the ego's centre."""
    for family, run_up in (("CBNA-50", 17.0), ("cyclist_from_kerb", 5.0)):
        for case in itertools.chain(FAMILIES[family].cases([0]),
                                    FAMILIES[family].cases([1000, 2000])):
            world = drive_unbraked(case.scenario())
            assert world.collision is not None, case.name
            # the cyclist's lateral offset while moving: a steady rate from run_up on
            world = World(case.scenario())
            moving_from: float | None = None
            while world.collision is None:
                world.step(DT, 0.0)
                bike = world.bodies()[0]
                if moving_from is None and abs(bike.vy_mps) > 0:
                    moving_from = abs(bike.y_m)
                    assert abs(bike.vy_mps) == pytest.approx(15 / 3.6, rel=0.11), case.name
            assert moving_from == pytest.approx(run_up, abs=0.6), case.name


def test_a_braking_lead_decelerates_to_a_stop_after_its_trigger():
    sc = case_of("CCRb", 50.0, decel_mps2=6, gap_m=40).scenario()
    motion = sc.object[0].motion
    assert motion is not None and motion.decel_mps2 == 6.0 and motion.brake_after_s == 2.0
    world = World(sc)
    world.step(1.9, 0.0)
    assert world.bodies()[0].vx_mps == pytest.approx(50 / 3.6)
    world.step(0.1, 0.0)
    for _ in range(50):                      # 0.5 s of braking at 6 m/s^2
        world.step(0.01, 0.0)
    assert world.bodies()[0].vx_mps == pytest.approx(50 / 3.6 - 3.0, abs=0.02)
    while world.collision is None:
        world.step(0.01, 0.0)
    assert world.bodies()[0].vx_mps == 0.0      # it stopped; the ego ran into it


def test_points_outside_the_grid_are_refused():
    with pytest.raises(ValueError, match="no grid point"):
        case_of("CCRs", 35.0, offset=0)
    with pytest.raises(ValueError, match="no grid point"):
        case_of("CCRs", 30.0, offset=10)
    with pytest.raises(KeyError):
        case_of("CCRx", 30.0)
    # Bend cases only where a driver takes the bend (lateral acceleration).
    radii = {float(dict(p)["radius_m"]) for v, p in FAMILIES["bend_stopped_car"].grid()
             if v == 60.0}
    assert 50.0 not in radii and 100.0 in radii
    assert all((v / 3.6) ** 2 / abs(float(dict(p)["radius_m"])) <= 5.0
               for v, p in FAMILIES["bend_stopped_car"].grid())


def test_the_command_line_lists_shows_and_writes_cases(tmp_path, capsys):
    assert main(["--list"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in FAMILIES) and "heldout 2000-9999" in out
    assert main(["--family", "CCRs", "--speed", "30", "--param", "offset=-25", "--show"]) == 0
    shown = capsys.readouterr().out
    assert "CCRs_30kph_offset-25_s0" in shown and 'kind = "car"' in shown
    assert main(["--family", "ghost", "--speed", "20", "--seeds", "heldout:2",
                 "--write", str(tmp_path)]) == 0
    files = sorted(tmp_path.glob("*.toml"))
    assert len(files) == 3 * 2                     # three ranges, two seeds
    for f in files:
        sc = load_scenario(f)
        assert sc.name == f.stem and sc.kind is ScenarioKind.NO_THREAT
    assert main(["--family", "CCRs", "--param", "offset=7", "--show"]) == 2
    assert "no case matches" in capsys.readouterr().err
    assert main(["--family", "nope", "--show"]) == 2


def test_bend_families_place_the_ego_on_a_bend_it_follows():
    sc = case_of("parked_cars_bend", 30.0, radius_m=50).scenario()
    assert sc.road.radius_m == 50.0
    world = World(sc)
    world.step(2.0, 0.0)
    assert world.yaw_rate_dps() == pytest.approx(math.degrees(30 / 3.6 / 50.0))
