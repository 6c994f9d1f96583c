"""Trained policies: weights-only loading, the CPU-independent forward pass, the training's wrappers.

Above ``core``: :mod:`.inference` (the network's actions, the same bits on every CPU), :mod:`.policy`
(run directories, observation wrappers and normalisation replayed on raw observations,
:class:`~.policy.LearnedPolicy`), :mod:`.curricula` (training-only wrappers), :mod:`.parameter_sharing`
(one network for every robot of a PettingZoo env), :mod:`.zoo` (the shipped policies, by name), and policies
trained elsewhere: :mod:`.onnx_policy` (ONNX graphs), :mod:`.sb3_zip` (SB3 zips, with :mod:`.torch_zip`
reading their tensors without unpickling) and their :mod:`.sidecar`.
"""
