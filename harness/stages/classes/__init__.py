"""Model classes of the sms stage: one object per class, one module per kind (springs,
p1 and its fitted materials, mt), each registered by name in
``harness.registry.MODEL_CLASSES`` (the names a case's ``[model] classes`` and
``calibrate --model`` take; its ``about`` says what each is). The stage loops over the
classes a case names and asks each through the protocol of
:class:`harness.stages.classes.base.ModelClass`, stated in docs/design.md ("Registries").
"""
