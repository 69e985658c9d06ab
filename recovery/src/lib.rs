//! Return routes: from the car's pose after a test back to the recovery route, and their shortening.
