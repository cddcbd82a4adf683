"""The paper's reproduction: ``reproduce`` runs the models (``models``) over the pillar
scene's layouts, ``summary`` builds summary.json and its markdown, ``figures`` draws the
paper's figures."""
