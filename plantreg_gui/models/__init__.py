"""The application models: the state of the registration workspace (:mod:`.registration`,
:mod:`.layers`), the landmark page (:mod:`.landmarks`) and the calibration wizard
(:mod:`.calibration`), without Qt, on one small event mechanism (:mod:`.events`). Every
mutation goes through a model method that emits; windows and pages are views of a model that
subscribe to its events (napari's evented models). Tests drive the models without a display.

Layering: the GUI imports the models, the models import the core, never the other way
(import-linter contracts in ``pyproject.toml``).
"""
