"""A sensor class names the component of the drone's actor that delivers its data (``delivery``, a
:class:`aerodaas.plugins.sensor.Delivery`): the built-ins by their contract, a plug-in by subclassing, a bad
declaration refused when the class is defined."""
from __future__ import annotations

import pytest

from aerodaas.config.robot import sensor_class
from aerodaas.plugins.sensor import ActorProducedSensor, Delivery, FrameSensor, SensorPlugin


@pytest.mark.parametrize("type_, delivery", [("camera", Delivery.CAMERA), ("odometry", Delivery.VEHICLE_STATE),
                                             ("stat_stream", Delivery.MISSION_STATUS)])
def test_each_builtin_sensor_names_its_component(type_, delivery):
    assert sensor_class(type_).delivery is delivery


def test_a_plugin_sensor_is_sampled_and_a_camera_of_its_own_delivers_frames():
    class Gas(SensorPlugin):
        def sample(self, state, t):
            return None

    class Thermal(FrameSensor):
        pass

    assert Gas.delivery is Delivery.SAMPLED and Gas.delivery.sampled and not Gas.delivery.frames
    assert Thermal.delivery.frames and not Thermal.delivery.sampled


def test_which_component_a_run_builds():
    assert Delivery.SAMPLED.has_component(subscribed=False, recorded=False)
    assert Delivery.CAMERA.has_component(subscribed=False, recorded=True)
    assert not Delivery.CAMERA.has_component(subscribed=False, recorded=False)
    for d in (Delivery.VEHICLE_STATE, Delivery.MISSION_STATUS):  # the drone records these itself
        assert d.has_component(subscribed=True, recorded=False) and not d.has_component(False, True)


def test_a_delivery_that_is_no_member_is_refused_naming_the_class():
    with pytest.raises(TypeError, match=r"Tagged: delivery must be a member of aerodaas\.plugins\.sensor\.Delivery, "
                                        r"got 'camera'"):
        class Tagged(SensorPlugin):
            delivery = "camera"


def test_an_actor_produced_sensor_without_a_component_is_refused():
    with pytest.raises(TypeError, match=r"Orphan: .*a Delivery other than SAMPLED"):
        class Orphan(ActorProducedSensor):
            pass
