"""The public Python API as users import it — the one place the docs name module paths.

``docs/conf.py`` writes one reference page per entry of :data:`PAGES` (autodoc of each name);
``tests/test_docstring_examples.py`` runs the Examples of the same names.  After a module
moves, only this list changes: users keep importing the names on the left.
"""

#: page name -> (title, what the page is about, the documented names)
PAGES = {
    "physics": ("physics", "Simulate a device, read its frequency response, load device files.", [
        "physics.simulate", "physics.frequency_response", "physics.load_device", "physics.available_devices",
        "physics.Device", "physics.FrequencyResponse", "physics.SimulationResult", "physics.InputError",
        "physics.ModelError",
    ]),
    "physics.signals": ("physics.signals", "Excitation voltages: swept sines, tones, pulses, steps, multisines, noise.", [
        "physics.signals.Signal", "physics.signals.sweep", "physics.signals.tone", "physics.signals.square",
        "physics.signals.steps", "physics.signals.multisine", "physics.signals.noise", "physics.signals.fade_in",
    ]),
    "physics.effects": ("physics.effects", "The effect contract: write, register and check an effect.", [
        "physics.effects.OutputEffect", "physics.effects.LoadEffect", "physics.effects.InputEffect",
        "physics.effects.register",
        "physics.effects.load_effects_file", "physics.effects.check_effect", "physics.ContractReport",
        "physics.effects.EFFECTS",
    ]),
    "nnmodel": ("nnmodel", "Load a trained network and predict with it; check a network class.", [
        "nnmodel.load", "nnmodel.bundle.Bundle", "nnmodel.check_model",
    ]),
}
