"""salad: text-driven human motion generation and attention-based editing (SALAD, KeyMotion).

The library part: no plotting imports (figures are ``salad_viz``'s, which depends only on
``salad_core.skeleton``). This docstring is the map: every module's job in a line, then where each
equation of the SALAD paper (CVPR 2025 and its supplement) and its Algorithm 1 live. README.md has
the entry points; ``tests/test_module_layout.py`` checks that every name below exists.

Modules
-------
pipeline       ``SaladPipeline``: text -> motion, ``edit``, ``invert``; the shipped weights by default
sampling       diffusion schedules, classifier-free guidance and the one denoising loop
models         the networks: skeleto-temporal VAE, skeleton-aware denoiser, attention sites and kernels
attention      cross-attention capture; hooks, caches, patching on every site; the paper's edits and more; inversion
vocabulary     what the weights were trained to read: training vocabularies, unknown-word checks and warnings
text           text encoders (CLIP, MiniLM) behind the ``TextEncoder`` protocol, word <-> token maps
skeleton       the HumanML3D and KIT-ML skeletons: joints, the 7 body parts, the feature layout
motion         joints <-> 263-d features (``recover_from_ric``), mirroring, normalisation
recovery       joints from decoded features with fixed bone lengths and planted feet (``out.joints``)
side_check     the sides a prompt names and a motion uses; when mirroring makes them agree
side_words     the words that name a side, and the caption of a mirror image (left <-> right swapped)
part_activity  how much each body part moves (part speeds, each in the part's own frame)
quaternion     quaternion and rotation-matrix helpers for numpy and torch
retarget       re-pose a motion on another rig's rigid torso (HumanML3D's), every limb kept
bvh            BVH motion-capture import: read a take, map its rig, convert to features
data           the HumanML3D layout and loaders; ``data.procedural``: the embedded motion-language corpus
train          VAE and denoiser trainers (one ``fit`` loop), consistency distillation, configs, batching, latent cache
keymotion      KeyMotion: keyframe selection, keyframe VAE, Parallel Skip Transformer, MMAE, pipeline
eval           T2M evaluator and metrics, the protocol, tables, the paper's numbers, physics benchmark
ablation_models the shipped ablation models (Tables 2-3, supplement Tables 2-4) and the study's reading
bench          ``salad bench``: speed, roofline fraction, overheads, memory, training rate
io             safe, atomic checkpoint and output files (safetensors with their configs)
limits         what is accepted from outside (files, weight folders, prompts): named limits, their checks
allocator      keep freed memory for reuse (glibc ``mallopt``), as the ``salad`` command does
lazy           packages whose exports are imported on first use (no torch on import)
openmp         how OpenMP worker threads wait between parallel regions (the command line sets it)
cli            the ``salad`` command, on top: a module per command group; draws (salad_viz), tunes the process
weights        the shipped weights and model cards (data, not code)

The paper, equation by equation
-------------------------------
eq. 1    STConv(h) = SkelConv(h) + TempConv(h)          salad_core.models.layers.STConv
eq. 2    STPool(h) = TempPool(SkelPool(h))              salad_core.models.layers.STPool
         STUnpool, the decoder's inverse (supp. A.1)    salad_core.models.layers.STUnpool
         the VAE: encoder, latent, decoder              salad_core.models.vae.MotionVAE
eq. 3    L_VAE = L_m + l_pos L_pos + l_vel L_vel + ...  salad_core.models.vae.MotionVAE.loss
         (its training step)                            salad_core.train.vae_trainer.VAEObjective
eqs. 4-6 TempAttn, SkelAttn, CrossAttn, each with FiLM  salad_core.models.denoiser.STTransformerLayer
eq. 10   FiLM(z, t) = gamma_t * z + beta_t              salad_core.models.denoiser.FiLM
eqs. 11-12 FFN with FiLM, the layer's output            salad_core.models.denoiser.STTransformerLayer
         the denoiser of Fig. 2 (skips, embeddings)     salad_core.models.denoiser.Denoiser.forward
         positional embedding (supp. A.2)               salad_core.models.embeddings.PositionalEmbedding
         timestep embedding for FiLM (supp. A.2)        salad_core.models.embeddings.TimestepEmbedding
eq. 7    v_t = alpha_t eps - sigma_t x                  salad_core.sampling.training_target
eq. 8    L_denoiser = ||v_hat - v||^2                   salad_core.train.denoiser_trainer.DenoiserObjective
         caption dropping with p_uncond                 salad_core.train.denoiser_trainer.prepare_denoiser_batch
eq. 9    CFG: v_hat = v(null) + w (v(c) - v(null))      salad_core.sampling.Guidance.combine
         the guided prediction of a step (a strategy)   salad_core.sampling.GuidedPrediction
         DDIM sampling (50 steps), the loop             salad_core.sampling.denoise
eq. 13   scaled-linear betas (supp. A.3)                salad_core.sampling.DiffusionConfig
         schedulers and solvers                         salad_core.sampling.make_scheduler

Algorithm 1 (zero-shot editing, supp. B), batched into one forward per step:
         the entry point                                salad_core.pipeline.SaladPipeline.edit
         the loop over both branches                    salad_core.attention.editing.edit_latents
         their rows in one forward (a loop strategy)    salad_core.attention.editing.EditPrediction
         Edit(M_t, M*_t, t) and its stores              salad_core.attention.controller.EditController
         word swap (tau = 0.8 T)                        salad_core.attention.edits.WordSwap
         prompt refinement                              salad_core.attention.edits.Refine
         its alignment A(.)                             salad_core.attention.align.global_align
         attention re-weighting (s in [-3, 3])          salad_core.attention.edits.Reweight
         attention mirroring, C(j)                      salad_core.attention.edits.Mirror
         (C over the body parts)                        salad_core.attention.edits.mirror_permutation
         Algorithm 1 as the official code runs it       salad_core.bench.naive_algorithm1.naive_algorithm1
         (three separate forwards, for timing)
Cross-attention maps as figures (Fig. 6): ``salad_viz.plot_attention_grid``; the T2M protocol of
Table 1 and Fig. 5: ``salad_core.eval.protocol``; the paper's own numbers:
``salad_core.eval.paper_tables``.
"""
# Importing salad_core changes nothing in the process: the salad command line (salad_core.cli) chooses the OpenMP
# wait policy and tunes the allocator before a command loads torch; salad_core.openmp.configure() does the first
# for a Python program that wants it.
__version__ = "0.7.0"
