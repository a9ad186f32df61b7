"""The 3-D robot that walks on a linkage: the LEGO build and its layers, the leg, the gait,
the hexapod's parts and floors, its two MuJoCo models, the walk and when it breaks, frail
legs, walk maps, the walking fitness and what the walk model learns from.

It reads linkages through `sim.linkage`; MuJoCo is loaded only by the modules that walk."""
