"""Display names of the table columns (the paper's model names), shared by configs, tables and figures."""

MODEL_LABELS = {
    "se": "SE",
    "hnn": "HNN",
    "atlas_tanh": "ATLAS-NN (tanh)",
    "atlas_exp": "ATLAS-NN (exp)",
    "hnn_baseline": "HNN (baseline)",
    "hnn_transfer": "HNN (transfer)",
    "atlas_tanh_transfer": "ATLAS-NN (tanh, transfer)",
    "atlas_exp_transfer": "ATLAS-NN (exp, transfer)",
    "hnn_march": "HNN (time-marching)",
    "atlas_tanh_march": "ATLAS-NN (tanh, time-marching)",
    "atlas_exp_march": "ATLAS-NN (exp, time-marching)",
}
