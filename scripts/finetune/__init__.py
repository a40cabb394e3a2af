"""Fine-tuning of the COCO NanoDet on grayscale fisheye frames (scripts/finetune_detector)."""
