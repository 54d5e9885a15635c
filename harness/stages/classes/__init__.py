"""Model classes of the sms stage: one object per class, one module per kind (springs,
p1, mt), each registered by name in ``harness.registry.MODEL_CLASSES`` (the names a case's
``[model] classes`` and ``calibrate --model`` take; its ``about`` says what each is). The
stage loops over the classes a case names and asks each (the protocol of
:class:`harness.stages.classes.base.ModelClass`):

- ``spec(spec)``: the case's [model] table as the class builds it;
- ``skip(case, label)``: a row saying why it has no model for this case, or None;
- ``build(case, spec, seed)``: its network on the case's nodes;
- ``label(spec, case)``: the stem of the rows' ``model`` column;
- ``rules(spec)``: the unfitted rows it scores (stiffness rules, or its own one);
- ``fit_runs(runs)``: which of the case's optimiser runs it takes;
- ``fit(setting, run, start, first)``: one fitted row, its network and trace;
- ``columns(case, spec, net)`` / ``constants(net)``: columns of all its rows / of its
  unfitted rows;
- ``save(ctx, net, res, tag)``: its files besides the stage's deformed-<tag>.npz.
"""
