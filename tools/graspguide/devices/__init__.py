"""The devices a host talks to: the port registry (:func:`.registry.open_port`), the
simulated device, the m4f firmware on QEMU, the Pro Mini sketch under simavr, their
builds, and the device session a run keeps open."""
