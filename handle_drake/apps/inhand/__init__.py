"""In-hand manipulation by action-gist guided motor babbling (report section 5).

Data flow::

    glove recording (glove.py) --four rules (mapping.py)--> Shadow command trajectory
        --segmentation (gist.py)--> action gist: ordered meta motions
        --eq. 45--> control-parameter vector c, bounds (one direction per variation)
        --Algorithm 1 / eq. 46 (gist.py, GistMotionSource)--> joint-angle frames -> hand.position
    in-hand trial (task.py): stable grasp, replay frames, checks, score (evaluation.py)
    optimisers (optimizers.py): Algorithm 2 incremental PSO, standard PSO, CMA-ES, random,
        all ask/tell and run through the babbling trial log and runner (experiment.py)
"""
