"""Real-data benchmarks: ``paz6d benchmark lmo`` (:mod:`paz6d.benchmark.lmo`) trains a detector and one pose
model per object on synthetic images of the LM-O meshes only and scores them on the real LM-O frames."""
