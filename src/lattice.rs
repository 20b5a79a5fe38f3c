//! Permutohedral-lattice bilateral filter (Adams, Baek & Davis 2010). (Being implemented.)
