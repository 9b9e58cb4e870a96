"""The paper's own board, the Arduino Pro Mini 3.3 V / 8 MHz (promini/): building its
sketch with arduino-cli offline (:mod:`graspguide.promini.build`)."""
