"""Protocol forms come from the protocol SPECS; bad values give a message, not an exception."""

import dataclasses

import pytest

from hilbench.bench.acquisition.protocols import PROTOCOLS
from hilbench.bench.gui.connection_panel import can_urls
from hilbench.bench.gui.protocol_panel import ProtocolPanel


@pytest.fixture
def panel(qtbot, tmp_path):
    p = ProtocolPanel(runs_dir=tmp_path)
    qtbot.addWidget(p)
    return p


def test_every_spec_has_a_field_with_its_unit_and_range(panel):
    for name, cls in PROTOCOLS.items():
        form = panel.forms[name]
        assert set(form.fields) == set(cls.specs())
        for field, spec in cls.specs().items():
            assert form.units[field].text() == (spec.unit_for("current") if spec.unit else "")
            if spec.minimum is not None and spec.maximum is not None:
                assert f"[{spec.minimum:g}, {spec.maximum:g}]" in form.fields[field].toolTip()


def test_default_forms_build_the_default_protocols(panel):
    for name, cls in PROTOCOLS.items():
        panel.select(name)
        protocol = panel.validate()
        assert protocol == cls(), name
        assert panel.start_button.isEnabled()
        assert panel.out_edit.text().endswith(".h5") and name in panel.out_edit.text()


def test_out_of_range_value_is_reported_and_blocks_start(panel):
    form = panel.select("identification")
    form.set_value("amplitude", "5000")
    assert panel.validate() is None
    assert "amplitude" in panel.summary.text() and "outside" in panel.summary.text()
    assert "A" in panel.summary.text()  # the unit is named
    assert not panel.start_button.isEnabled()
    assert form.fields["amplitude"].styleSheet()  # the field is marked
    form.set_value("amplitude", "abc")
    assert "not a number" in panel.summary.text()
    form.set_value("amplitude", "4")
    assert panel.validate().amplitude == 4.0 and panel.start_button.isEnabled()
    form.set_value("sample_rate", "2000")
    form.set_value("cutoff", "1500")  # inside its range, but above Nyquist: a cross-field check
    assert panel.validate() is None and "Nyquist" in panel.summary.text()


def test_velocity_mode_changes_setpoint_units(panel):
    form = panel.select("chirp")
    form.set_value("mode", "velocity")
    assert form.units["gain"].text() == "rad/s"
    assert panel.validate().mode == "velocity"


def test_stepped_sine_lists(panel):
    form = panel.select("stepped_sine")
    form.set_value("frequencies", "1, 2.5; 10")
    form.set_value("amplitudes", "0.5")
    p = panel.validate()
    assert p.frequencies == (1.0, 2.5, 10.0) and p.amplitudes == (0.5,)
    assert "3 steps" in panel.summary.text()


def test_existing_output_file_is_refused(panel, tmp_path, qtbot):
    existing = tmp_path / "x.h5"
    existing.write_bytes(b"")
    panel.out_edit.setText(str(existing))
    with qtbot.assertNotEmitted(panel.start_requested):
        panel.start_button.click()
    assert "exists" in panel.summary.text()


def test_can_urls_from_sysfs(tmp_path):
    for name, kind in (("can0", "280"), ("eth0", "1"), ("vcan1", "280")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "type").write_text(kind + "\n")
    assert can_urls(str(tmp_path)) == ["can://socketcan/can0", "can://socketcan/vcan1", "can://virtual/bench0"]


def test_protocol_defaults_exist_for_every_field():
    for cls in PROTOCOLS.values():
        for f in dataclasses.fields(cls):
            assert f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING


@pytest.mark.parametrize("protocol", [
    PROTOCOLS["identification"](duration=1.2345),
    PROTOCOLS["chirp"](duration=0.5, sample_rate=2000),
    PROTOCOLS["stepped_sine"](frequencies=(3.3, 7.1, 13.7), amplitudes=(1.0, 2.0), settle_periods=2,
                              measure_periods=3, sample_rate=5000),
    PROTOCOLS["stepped_sine"](frequencies=(1.7,), amplitudes=(1.0,), settle_periods=4, measure_periods=6,
                              sample_rate=1000),
])
def test_planned_samples_match_the_setpoints(protocol):
    from hilbench.bench.gui.protocol_panel import planned_samples

    samples, steps = planned_samples(protocol)
    assert samples == protocol.setpoints().size  # exact: the same snapping rule, no setpoints built
    assert steps == len(protocol.segments())


def test_excitation_checks_reach_the_form(panel):
    form = panel.select("stepped_sine")
    form.set_value("sample_rate", "1000")
    form.set_value("frequencies", "300")  # inside the spec's range, above fs/4 for the excitation
    assert panel.validate() is None and "Nyquist" in panel.summary.text()


def test_device_settings_are_checked(panel):
    from hilbench.bench.acquisition.runner import DeviceSettings

    assert panel.validate() is not None and panel.settings == DeviceSettings()
    panel.device_form.set_value("current_limit", "-1")
    assert panel.validate() is None and "current_limit" in panel.summary.text()
    panel.device_form.set_value("current_limit", "2")
    form = panel.select("identification")  # default amplitude 5 A is beyond a 2 A limit
    assert panel.validate() is None and "limit" in panel.summary.text()
    form.set_value("amplitude", "0.5")
    assert panel.validate() is not None and panel.settings.current_limit == 2.0


def test_presliding_shows_its_recommended_gains_unless_the_operator_set_them(panel):
    """Choosing presliding puts its RECOMMENDED_SETTINGS in the device form (as `hilbench run` does), leaving the
    others at the defaults; another protocol puts the defaults back; a field the operator typed in is kept."""
    from hilbench.bench.acquisition.protocols import Presliding
    from hilbench.bench.acquisition.runner import DeviceSettings

    panel.select("presliding")
    settings = panel.device_form.settings()
    assert settings.position_kp == Presliding.RECOMMENDED_SETTINGS["position_kp"] == 100.0
    assert settings.position_i_limit == DeviceSettings().position_i_limit
    panel.select("identification")
    assert panel.device_form.settings().position_kp == DeviceSettings().position_kp
    panel.device_form.set_value("position_ki", 1234.0)  # the operator's own value
    panel.select("presliding")
    assert panel.device_form.settings().position_ki == 1234.0
    assert panel.device_form.settings().position_kd == 0.5
