"""Files in and out: SSP archives, output claims, log recovery, run logs (reading them back, bounded)."""
