"""The case: schema, case files, materials, load sets, boundary parts, fibre fields.
Imports no model, stage or report code."""
