"""The connection panel's one-line device identity: a v3 device that names its temperature sensor says so."""

from hilbench.bench.gui.connection_panel import identity_text

BASE = {"model": "HB-SIM-1", "serial": "SIM-0001", "firmware": "hilbench-sim c-core 3.0.0", "protocol_version": 3,
        "buffer_capacity": 8192}


def test_identity_names_the_temperature_sensor_only_when_the_device_has_one():
    assert identity_text({**BASE, "sensors": 1}).endswith("buffer 8192  senses winding temperature")
    assert identity_text({**BASE, "sensors": 0}).endswith("buffer 8192")
    assert identity_text(BASE).endswith("buffer 8192")  # a v2 device's identity has no sensors entry
