"""Instance segmentation: a crop-then-segment mask head (Mask R-CNN's mask branch on square crops around
detection boxes), trained on ``paz6d generate`` data sets (``paz6d train segmentation``)."""
